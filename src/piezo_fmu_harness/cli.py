"""``piezo-fmu``: the nominal case, sweeps, the two designs, the load, the frequency response and
the optimiser, all through the FMU with fmpy.

    piezo-fmu nominal [--out DIR] [--stop-time S] [--step S] [--set NAME=VALUE ...]
    piezo-fmu sweep (--grid NAME=START:STOP:COUNT ... | --preset NAME | --config FILE.toml)
                    [--set NAME=VALUE ...] [--stop-time S] [--step S] [--out DIR] [--jobs N]
                    [--scheduler ADDRESS | --dask-local] [--resume | --force] [--damping eq29|ls]
    piezo-fmu two-designs [--out DIR] [--stop-time S] [--step S]
    piezo-fmu load-sweep [--r-min OHM] [--r-max OHM] [--count N] [--models 1,2] [--set NAME=VALUE ...]
                         [--stop-time S] [--step S] [--impact-step S] [--out DIR] [--jobs N]
    piezo-fmu impact-voltage [--load OHM ...] [--models 0,1,2] [--step S] [--set NAME=VALUE ...] [--out DIR]
    piezo-fmu frequency-response [--amplitude M | --acceleration M/S2] [--ratio-min R] [--ratio-max R] [--count N]
                                 [--load OHM] [--voltage-model N] [--set NAME=VALUE ...] [--samples N]
                                 [--tolerance TOL] [--max-cycles N] [--newton-iterations N] [--out DIR]
                                 [--jobs N] [--scheduler ADDRESS | --dask-local] [--resume | --force]
    piezo-fmu optimize --param NAME=LO:HI ... [--objective perfectibility|forced] [--weight TERM=W ...]
                       [--reference TERM=VALUE ...] [--damping eq29|ls] [--maxiter N] [--popsize N] [--seed N]
                       [--polish] [--no-grid] [--sensitivity-step F] [frequency-response's band options]
                       [--out DIR] [--jobs N] [--scheduler ADDRESS | --dask-local] [--resume | --force]
    piezo-fmu presets

Values are SI (m, kg, s, V). Bad input (an unknown parameter, an empty or reversed range, a
value outside the bounds of the FMU's modelDescription, an unwritable output folder) is
reported before anything runs, with exit status 2. An interrupted sweep exits with 130 and
keeps every finished point; run the same command with ``--resume`` to finish it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

from . import commands, commands_forced, commands_load, presets
from .checks import PROG
from .spec import DEFAULT_STOP_TIME, DEFAULT_SWEEP_STEP, UsageError

TOML_HELP = """

A --config file (SI units; the command line's --grid, --set, --stop-time and --step override it):

  stop_time = 2.0
  step = 0.1
  out = "results/x1-m"
  [grid]
  x1 = "0:0.03:31"                              # START:STOP:COUNT
  m = {start = 0.02, stop = 0.2, count = 31}
  # d = [0.004, 0.006, 0.008]                   # or explicit values, increasing
  [set]
  d = 0.008
"""


def _parser() -> argparse.ArgumentParser:
    from . import frequency_response as fr

    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def model_options(sub) -> None:
        sub.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                         help="set an FMU parameter (SI), repeatable")
        sub.add_argument("--fmu", type=Path, default=None,
                         help="the FMU (default $PIEZO_FMU, else the FMI 2.0 FMU installed with the package)")

    def common(sub, step_default: float, step_help: str) -> None:
        sub.add_argument("--stop-time", type=float, default=None, metavar="S",
                         help=f"duration simulated, s (default {DEFAULT_STOP_TIME:g})")
        sub.add_argument("--step", type=float, default=None, metavar="S",
                         help=f"communication step, s (default {step_default:g}; {step_help})")
        model_options(sub)

    def band_options(sub, defaults: dict) -> None:
        """The harmonic base motion, the band of frequencies and the steady-state settings."""
        amplitude = sub.add_mutually_exclusive_group()
        amplitude.add_argument("--amplitude", type=float, default=None, metavar="M",
                               help="base displacement amplitude Y, m (default 1e-3)")
        amplitude.add_argument("--acceleration", type=float, default=None, metavar="M/S2",
                               help="base acceleration amplitude A, m/s^2 (then Y = A / w^2 at each frequency)")
        for option, kind, metavar, text in (
                ("--ratio-min", float, "R", f"lowest frequency, as w / sqrt(K/M) (default {defaults['ratios'][0]:g})"),
                ("--ratio-max", float, "R", f"highest frequency, as w / sqrt(K/M) (default {defaults['ratios'][1]:g})"),
                ("--count", int, "N", f"frequencies, evenly spaced (default {defaults['count']})"),
                ("--load", float, "OHM", "load R_load of each patch, Ohm (default 1/(omega_c C_p), near the optimum)"),
                ("--voltage-model", int, "N", "0 quasi-static (nothing harvested), 1 circuit one-way, 2 circuit "
                                              "coupled (default 1)"),
                ("--samples", int, "N", "communication steps per forcing period (default 64)"),
                ("--tolerance", float, "TOL", "steady state: the section returns within TOL * Y (default 1e-6)"),
                ("--max-cycles", int, "N", f"cap on the forcing cycles simulated per frequency (default "
                                           f"{defaults['max_cycles']})"),
                ("--newton-iterations", int, "N", "Newton iterations per shooting attempt; 0 marches in time only "
                                                  "(default 12)")):
            sub.add_argument(option, type=kind, default=None, metavar=metavar, help=text)

    def results_folder(sub, name: str) -> None:
        sub.add_argument("--out", type=Path, default=Path("results") / name, metavar="DIR",
                         help=f"results folder (default results/{name})")

    def jobs(sub) -> None:
        sub.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")

    def engine(sub) -> None:
        """Where the points run, and what to do with a folder that holds some already."""
        jobs(sub)
        where = sub.add_mutually_exclusive_group()
        where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
        where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")
        again = sub.add_mutually_exclusive_group()
        again.add_argument("--resume", action="store_true",
                           help="finish the run in --out: run only the points not yet recorded")
        again.add_argument("--force", action="store_true", help="start over, discarding the points in --out")
        sub.add_argument("--no-progress", action="store_true", help="no progress bar")

    nominal = commands.add_parser("nominal", help="the nominal case (Fig. 3): time series, summary, figures")
    common(nominal, 1e-4, "the time series' sampling")
    results_folder(nominal, "nominal")

    sweep = commands.add_parser(
        "sweep", help="a sweep over FMU parameters (Figs. 4-9)",
        description="Run every point of a full-factorial grid through the FMU; write NetCDF, a tidy "
                    "CSV, the zones and contour figures. Presets:\n" + presets.describe() + TOML_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    common(sweep, DEFAULT_SWEEP_STEP, "the metrics do not depend on it")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=START:STOP:COUNT",
                       help="sweep a parameter over COUNT evenly spaced values (SI), repeatable")
    sweep.add_argument("--preset", choices=presets.preset_names(), metavar="NAME",
                       help=f"a built-in sweep: {', '.join(presets.preset_names())}")
    sweep.add_argument("--config", type=Path, metavar="FILE.toml",
                       help="grids and values from a TOML file ([grid], [set], stop_time, step, out)")
    sweep.add_argument("--out", type=Path, default=None, metavar="DIR",
                       help="results folder (default results/PRESET for a preset, else results/sweep)")
    engine(sweep)
    sweep.add_argument("--zone-quantile", type=float, default=None, metavar="Q",
                       help="our zones are the points at or above this quantile of each metric (default 0.9)")
    sweep.add_argument("--damping", choices=("eq29", "ls"), default="eq29",
                       help="the damping measure that ranks the vibratory-based and design zones: eq29, the "
                            "paper's DI (default), or ls, DI_ls, the least-squares decay slope of the maxima")

    two = commands.add_parser("two-designs", help="the designed and the poor damper (Fig. 10) beside the paper")
    common(two, 1e-4, "the time series' sampling")
    results_folder(two, "two-designs")

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

    frequency = commands.add_parser(
        "frequency-response", help="steady-state response to harmonic base motion, swept up and down in frequency",
        description="Shake the damper's base as y = Y sin(w t) at --count frequencies from --ratio-min to "
                    "--ratio-max times sqrt(K/M); at each, find the periodic steady state (shooting, verified by "
                    "simulation) starting from the previous frequency's state, sweeping up and down, with and "
                    "without the damper. Writes frequency_response.nc/.csv, summary.json and amplitude.png, "
                    "power.png, impacts.png.")
    band_options(frequency, fr.BAND_DEFAULTS)
    model_options(frequency)
    results_folder(frequency, "frequency-response")
    engine(frequency)

    from . import continuation_study as cs

    continuation = commands.add_parser(
        "continuation", help="branches of periodic orbits followed through their folds, with their bifurcations",
        description="Seed with a sweep up and down (the frequency response's shooting, with the damper), then follow "
                    "every orbit with impacts by pseudo-arclength continuation in the frequency ratio (or Y, or a "
                    "damper parameter), through folds, naming the bifurcations (fold, period doubling, "
                    "Neimark-Sacker, grazing). Writes continuation.nc, branches.csv, events.csv, summary.json and "
                    "continuation.png.")
    continuation.add_argument("--parameter", default="ratio", metavar="NAME",
                              help="the continued parameter: ratio (default), Y, or a Real damper parameter")
    continuation.add_argument("--range", default=None, metavar="LO:HI", help="its range (not for ratio)")
    continuation.add_argument("--ratio", type=float, default=1.0, metavar="R",
                              help="w / sqrt(K/M) held fixed when the parameter is not the ratio (default 1)")
    continuation.add_argument("--max-points", type=int, default=Settings_default("max_points"), metavar="N",
                              help="points a branch may have in each direction (default %(default)s)")
    continuation.add_argument("--max-branches", type=int, default=cs.MAX_BRANCHES, metavar="N",
                              help="branches followed at most (default %(default)s)")
    band_options(continuation, cs.SEED_DEFAULTS)
    model_options(continuation)
    results_folder(continuation, "continuation")
    jobs(continuation)
    where = continuation.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
    where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")
    continuation.add_argument("--force", action="store_true", help="replace the results in --out")
    continuation.add_argument("--no-progress", action="store_true", help="(no progress bar is drawn)")

    from . import optimize as opt

    optimizer = commands.add_parser(
        "optimize", help="a design optimiser (differential evolution) over FMU parameters",
        description="Search --param parameters within bounds with scipy's differential_evolution, its evaluations "
                    "run in parallel on the sweep engine, to minimise J: under --objective perfectibility "
                    "-100 (w_DI DI/DI_ref + w_V V_rms/V_ref) over a free decay (eq. 31 with reference values); under "
                    "--objective forced w_amplitude peak_with/peak_without + w_transmissibility peak/Y - w_power "
                    "P/P_ref over a band of harmonic base motion. References are the reference design's (the FMU's "
                    "start values and --set) unless given. Reports the optimum, its sensitivity and the best point "
                    "of a grid of the same budget; every evaluation is appended to evaluations.jsonl (--resume).")
    optimizer.add_argument("--param", action="append", default=[], metavar="NAME=LO:HI",
                           help="a parameter to search and its bounds (SI), repeatable")
    optimizer.add_argument("--objective", choices=tuple(opt.TERMS), default="perfectibility",
                           help="perfectibility (free decay, default) or forced (harmonic base motion over a band)")
    optimizer.add_argument("--weight", action="append", default=[], metavar="TERM=W",
                           help="weight of a term: DI, V_rms (perfectibility; default 0.5 each) or amplitude, "
                                "transmissibility, power (forced; default 1, 0, 0.1)")
    optimizer.add_argument("--reference", action="append", default=[], metavar="TERM=VALUE",
                           help="reference value of a term, SI: DI (m/s), V_rms (V); power (W), amplitude_without (m) "
                                "(default: the reference design's)")
    optimizer.add_argument("--damping", choices=("eq29", "ls"), default="eq29",
                           help="the damping term of perfectibility: eq29 (default) or ls (DI_ls)")
    for option, kind, metavar, text in (
            ("--maxiter", int, "N", "generations of differential evolution at most (default 30; forced 8)"),
            ("--popsize", int, "N", "population per searched parameter (default 15; forced 6)"),
            ("--tol", float, "TOL", "differential evolution's relative tolerance (default 0.01)"),
            ("--seed", int, "N", "seed of the search (default 1): the same seed proposes the same designs"),
            ("--sensitivity-step", float, "F", "step of the sensitivity, a fraction of each range (default 0.02)")):
        optimizer.add_argument(option, type=kind, default=None, metavar=metavar, help=text)
    optimizer.add_argument("--polish", action="store_true",
                           help="polish the best design with L-BFGS-B (finite differences): for smooth objectives; "
                                "impacts make them piecewise, where it spends evaluations for nothing")
    optimizer.add_argument("--no-grid", action="store_true", help="no grid of the same budget to compare with")
    common(optimizer, DEFAULT_SWEEP_STEP, "free-decay runs of the perfectibility objective")
    band_options(optimizer, opt.BAND_DEFAULTS)
    results_folder(optimizer, "optimize")
    engine(optimizer)

    commands.add_parser("presets", help="list the built-in sweeps")
    return parser


def Settings_default(name: str):
    from .continuation import Settings

    return getattr(Settings(), name)


def _continuation(args) -> int:
    from . import continuation_study

    return continuation_study.command(args)


def main(argv: Optional[list[str]] = None) -> int:
    """Run the CLI; return the exit status (0 done, 2 bad input, 130 interrupted)."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse has printed its message
        return int(exit_.code or 0)
    try:
        if args.command == "presets":
            print(presets.describe())
            return 0
        return {"nominal": commands.nominal, "sweep": commands.sweep, "two-designs": commands.two_designs,
                "load-sweep": commands_load.load_sweep, "impact-voltage": commands_load.impact_voltage,
                "frequency-response": commands_forced.frequency_response,
                "optimize": commands_forced.optimize, "continuation": _continuation}[args.command](args)
    except UsageError as error:
        print(f"{PROG} {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
