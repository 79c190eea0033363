"""The design optimiser: differential evolution over FMU parameters, on the sweep engine, with the
perfectibility, the forced response or the response to random base excitation as its objective
(``piezo-fmu optimize``).

- :mod:`.search`: the problem, the objective and the search;
- :mod:`.band`, :mod:`.spectrum`: an evaluation of the forced objective (a sweep of the band
  through the FMU) and of the random one (the realizations on the batch engine);
- :mod:`.polish`: the polish of the best design (``--polish``);
- :mod:`.log`: ``optimize.json``, ``evaluations.jsonl``, and the check of its records on ``--resume``;
- :mod:`.report`: the report, the sensitivity, the grid of the same budget and the figure;
- :mod:`.command`: the command line.

Under ``--objective random`` this study reads the simulation core's batch engine
(``piezo_fmu.solver.batch``, in the worker, through :mod:`piezo_fmu_harness.random_response`);
under the others it reads nothing but the FMU.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu optimize``."""
    from ...spec import DEFAULT_SWEEP_STEP
    from ...options import band_options, common, damping_option, results_options, seed_option, work_options
    from ...random_response.arguments import STEPS_PER_TOP, excitation_options
    from . import search as opt
    from .command import optimize

    optimizer = commands.add_parser(
        "optimize", help="design optimisation (differential evolution)",
        description="Search --param parameters within bounds with scipy's differential_evolution, its evaluations "
                    "run in parallel on the sweep engine, to minimise J: under --objective perfectibility "
                    "-100 (w_DI DI/DI_ref + w_V V_rms/V_ref) over a free decay (eq. 31 with reference values); under "
                    "--objective forced w_amplitude peak_with/peak_without + w_transmissibility peak/Y - w_power "
                    "P/P_ref over a band of harmonic base motion; under --objective random w_ratio RMS_with/RMS_without "
                    "- w_power P/P_ref over --realizations realizations of random base acceleration under a PSD, "
                    "the same for every design, on the batch engine. References are the reference design's (the FMU's "
                    "start values and --set) unless given. Reports the optimum, its sensitivity and the best point "
                    f"of a grid of the same budget: {', '.join(opt.FILES)}; what was asked goes to optimize.json and "
                    "every evaluation to evaluations.jsonl (--resume).")
    optimizer.add_argument("--param", action="append", default=[], metavar="NAME=LO:HI",
                           help="a parameter to search and its bounds (SI), repeatable")
    optimizer.add_argument("--objective", choices=tuple(opt.TERMS), default="perfectibility",
                           help="perfectibility (free decay, default), forced (harmonic base motion over a band) or "
                                "random (random base acceleration under a PSD)")
    optimizer.add_argument("--weight", action="append", default=[], metavar="TERM=W",
                           help="weight of a term: DI, V_rms (perfectibility; default 0.5 each) or amplitude, "
                                "transmissibility, power, worst (forced; default 1, 0, 0.1, 0) or ratio, power "
                                "(random; default 1, 0)")
    optimizer.add_argument("--reference", action="append", default=[], metavar="TERM=VALUE",
                           help="reference value of a term, SI: DI (m/s), V_rms (V); power (W), amplitude_without (m) "
                                "(default: the reference design's)")
    damping_option(optimizer)
    for option, kind, metavar, text in (
            ("--maxiter", int, "N", "generations of differential evolution at most (default 30; forced, random 8)"),
            ("--popsize", int, "N", "population per searched parameter (default 15; forced, random 6)"),
            ("--tol", float, "TOL", "differential evolution's relative tolerance (default 0.01)"),
            ("--sensitivity-step", float, "F", "step of the sensitivity, a fraction of each range (default 0.02)")):
        optimizer.add_argument(option, type=kind, default=None, metavar=metavar, help=text)
    seed_option(optimizer)
    optimizer.add_argument("--polish", action="store_true",
                           help="polish the best design with Nelder-Mead in the unit box: for smooth objectives; "
                                "impacts make them piecewise, where it spends evaluations for nothing")
    optimizer.add_argument("--no-grid", action="store_true", help="no grid of the same budget to compare with")
    common(optimizer, DEFAULT_SWEEP_STEP, "free-decay runs of the perfectibility objective; under random, "
                                          f"{STEPS_PER_TOP} steps a period of the spectrum's highest frequency")
    band_options(optimizer, opt.BAND_DEFAULTS, voltage_model="1; 2 under --objective random, which takes 0 or 2")
    excitation_options(optimizer)
    results_options(optimizer, "optimize", resumable=True)
    work_options(optimizer)
    optimizer.set_defaults(run=optimize)
