"""The load study (issue 7): the load sweep of the circuit voltage models and the voltage of
one impact (``piezo-fmu load-sweep`` and ``piezo-fmu impact-voltage``).

- :mod:`.sweep`: the load sweep and its optimum;
- :mod:`.impacts`: the first impact, sampled finely;
- :mod:`.figures`: their figures;
- :mod:`.command`: the command line.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu load-sweep`` and ``piezo-fmu impact-voltage``."""
    from ...spec import DEFAULT_SWEEP_STEP
    from ...options import common, jobs, results_folder
    from .command import impact_voltage, load_sweep

    load = commands.add_parser(
        "load-sweep", help="harvested energy per impact and average power against the load R (circuit models)",
        description="Run the nominal case at loads log-spaced from --r-min to --r-max under each of --models; "
                    "write load_sweep.csv/.json/.md/.png with the optimum load beside R_opt ~ 1/(omega_c C_p), "
                    "then the voltage of the first impact at the paper's load and at the optimum.")
    common(load, DEFAULT_SWEEP_STEP, "the metrics do not depend on it")
    load.add_argument("--r-min", type=float, default=None, metavar="OHM",
                      help="lowest load, Ohm (default 1e3; voltage_model 2 refuses loads below about 352 Ohm)")
    load.add_argument("--r-max", type=float, default=None, metavar="OHM", help="highest load, Ohm (default 1e9)")
    load.add_argument("--count", type=int, default=None, metavar="N", help="loads, log-spaced (default 25)")
    load.add_argument("--models", default="1,2", metavar="LIST",
                      help="voltage models swept, comma-separated: 1 circuit one-way, 2 circuit coupled (default 1,2)")
    load.add_argument("--impact-step", type=float, default=None, metavar="S",
                      help="sampling of the single-impact figures, s (default 1e-6)")
    load.add_argument("--no-impact", action="store_true", help="skip the single-impact figures")
    results_folder(load, "load-sweep")
    jobs(load)

    impact = commands.add_parser(
        "impact-voltage", help="the voltage of the first impact under the voltage models, sampled finely",
        description="Sample the first impact of the nominal run under each of --models at each --load; write "
                    "impact_<load>.png and .csv and impact.json. --stop-time bounds the search for the impact.")
    common(impact, 1e-6, "the sampling of the impact")
    impact.add_argument("--load", action="append", type=float, default=[], metavar="OHM",
                        help="a load R, Ohm, repeatable (default: the FMU's R_load and 1/(omega_c C_p))")
    impact.add_argument("--models", default="0,1,2", metavar="LIST",
                        help="voltage models, comma-separated: 0 quasi-static, 1 circuit one-way, 2 coupled "
                             "(default 0,1,2)")
    results_folder(impact, "impact-voltage")
    load.set_defaults(run=load_sweep)
    impact.set_defaults(run=impact_voltage)
