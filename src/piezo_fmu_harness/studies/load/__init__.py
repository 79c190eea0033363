"""The load study: the load sweep of the circuit voltage models and the voltage of
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
    from ...options import common, count_option, models_option, results_options, work_options
    from .command import impact_voltage, load_sweep
    from .impacts import FILES as IMPACT_FILES
    from .sweep import DEFAULT_COUNT, FILES

    load = commands.add_parser(
        "load-sweep", help="harvested energy and power against the load",
        description="Run the nominal case at loads log-spaced from --r-min to --r-max under each of --models; "
                    f"write {', '.join(FILES)} with the optimum load beside R_opt ~ 1/(omega_c C_p), then the "
                    f"voltage of the first impact at the paper's load and at the optimum ({', '.join(IMPACT_FILES)}). "
                    "What was asked goes to loads.json and each point to points.jsonl (--resume).")
    common(load, DEFAULT_SWEEP_STEP, "the metrics do not depend on it")
    load.add_argument("--r-min", type=float, default=None, metavar="OHM",
                      help="lowest load, Ohm (default 1e3; voltage_model 2 refuses loads below about 352 Ohm)")
    load.add_argument("--r-max", type=float, default=None, metavar="OHM", help="highest load, Ohm (default 1e9)")
    count_option(load, DEFAULT_COUNT)
    models_option(load, "1,2")
    load.add_argument("--impact-step", type=float, default=None, metavar="S",
                      help="sampling of the single-impact figures, s (default 1e-6)")
    load.add_argument("--no-impact", action="store_true", help="skip the single-impact figures")
    results_options(load, "load-sweep", resumable=True)
    work_options(load)

    impact = commands.add_parser(
        "impact-voltage", help="the voltage of the first impact, sampled finely",
        description="Sample the first impact of the nominal run under each of --models at each --load; write "
                    f"{', '.join(IMPACT_FILES)}. --stop-time bounds the search for the impact.")
    common(impact, 1e-6, "the sampling of the impact")
    impact.add_argument("--load", action="append", type=float, default=None, metavar="OHM",
                        help="load R_load of each patch, Ohm (default the FMU's R_load and 1/(omega_c C_p); "
                             "give it again for more loads)")
    models_option(impact, "0,1,2")
    results_options(impact, "impact-voltage", resumable=False)
    load.set_defaults(run=load_sweep)
    impact.set_defaults(run=impact_voltage)
