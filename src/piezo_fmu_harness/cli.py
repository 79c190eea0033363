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
import math
import shutil
import signal
import sys
from pathlib import Path
from typing import Optional

import numpy as np

from . import presets
from .spec import DEFAULT_STOP_TIME, DEFAULT_SWEEP_STEP, UsageError

PROG = "piezo-fmu"
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
        return {"nominal": _nominal, "sweep": _sweep, "two-designs": _two_designs, "load-sweep": _load_sweep,
                "impact-voltage": _impact_voltage, "frequency-response": _frequency_response,
                "optimize": _optimize}[args.command](args)
    except UsageError as error:
        print(f"{PROG} {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


# -- shared steps ----------------------------------------------------------------------------------

def _model(args):
    from .fmu import FmuModel, default_fmu_path

    try:
        path = args.fmu or default_fmu_path()
        return FmuModel(path)
    except FileNotFoundError as error:
        raise UsageError(str(error)) from None
    except Exception as error:  # noqa: BLE001 - any unreadable FMU is bad input
        raise UsageError(f"--fmu {path}: cannot read the FMU: {error}") from None


def _assignments(model, texts: list[str]) -> dict:
    from .spec import parse_assignment

    return dict(parse_assignment(model, text) for text in texts)


def _times(args, step_default: float, config: Optional[dict] = None) -> tuple[float, float]:
    from .spec import check_times

    config = config or {}
    stop_time = args.stop_time if args.stop_time is not None else config.get("stop_time", DEFAULT_STOP_TIME)
    step = args.step if args.step is not None else config.get("step", step_default)
    check_times(stop_time, step)
    return stop_time, step


def _preflight(model, values_list: list[dict], where: str):
    """Extract the FMU, let one instance accept ``values_list``; return ``(unzipdir, instance)``."""
    from .fmu import Instance
    from .spec import check_with_fmu

    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        check_with_fmu(model, instance, values_list, where)
    except UsageError:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
        raise
    return unzipdir, instance


# -- nominal ---------------------------------------------------------------------------------------

def _nominal(args) -> int:
    from .nominal import NOMINAL_STEP, run_nominal, summary_lines
    from .spec import prepare_output_dir

    model = _model(args)
    overrides = _assignments(model, args.set)
    stop_time, step = _times(args, NOMINAL_STEP)
    out = prepare_output_dir(args.out)
    unzipdir, instance = _preflight(model, [overrides], "--set")
    try:
        summary = run_nominal(model, out, stop_time, step, overrides, instance=instance)
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    print("\n".join(summary_lines(summary)))
    return 0


# -- two designs -----------------------------------------------------------------------------------

def _two_designs(args) -> int:
    from .nominal import NOMINAL_STEP
    from .spec import prepare_output_dir
    from .two_designs import DESIGNS, run_two_designs, summary_lines

    model = _model(args)
    overrides = _assignments(model, args.set)
    clash = sorted(set(overrides) & {"x1", "m", "d"})
    if clash:
        raise UsageError(f"--set {clash[0]}: x1, m and d are what the two designs differ by; they cannot be set")
    stop_time, step = _times(args, NOMINAL_STEP)
    out = prepare_output_dir(args.out)
    unzipdir, instance = _preflight(model, [{**overrides, **d} for d in DESIGNS.values()], "two designs")
    instance.free()
    shutil.rmtree(unzipdir, ignore_errors=True)
    result = run_two_designs(model, out, stop_time, step, overrides)
    print("\n".join(summary_lines(result)))
    return 0


# -- load sweep and single impacts -----------------------------------------------------------------

def _voltage_models(model, args, allowed: tuple) -> tuple[int, ...]:
    """``--models`` as voltage_model numbers, each within the FMU's bounds and in ``allowed``."""
    parameter = model.parameters["voltage_model"]
    chosen = []
    for text in args.models.split(","):
        text = text.strip()
        try:
            number = parameter.coerce(int(text) if text.lstrip("-").isdigit() else text)
        except ValueError as error:
            raise UsageError(f"--models {args.models}: {error}") from None
        if number not in allowed:
            raise UsageError(f"--models {args.models}: voltage_model = {number} (quasi-static, an open circuit) "
                             f"harvests no energy; a load sweep takes voltage_model "
                             f"{' or '.join(map(str, allowed))}")
        if number not in chosen:
            chosen.append(number)
    return tuple(chosen)


def _load_value(model, value: float, option: str) -> float:
    """A load for ``R_load``: finite and > 0 (log spacing), within the modelDescription's bounds."""
    parameter = model.parameters["R_load"]
    if not (value > 0 and value < float("inf")):
        raise UsageError(f"{option} {value:g}: R_load = {value:g} Ohm must be a finite resistance > 0; "
                         "allowed range (0, inf) Ohm")
    try:
        return float(parameter.coerce(value))
    except ValueError as error:
        raise UsageError(f"{option} {value:g}: {error}") from None


def _circuit_overrides(model, args) -> dict:
    """``--set`` for the load commands; also checks the FMU declares what they read."""
    from .fmu import ENERGY_OUTPUTS
    from .load import CONSTANTS

    missing = ([n for n in ENERGY_OUTPUTS if n not in model.outputs]
               + [n for n in CONSTANTS if n not in model.calculated])
    if missing:
        raise UsageError(f"--fmu {model.path}: the FMU lacks {', '.join(missing)} (an FMU older than the circuit "
                         "voltage models' harvested energy outputs); rebuild it")
    overrides = _assignments(model, args.set)
    clash = sorted(set(overrides) & {"R_load", "voltage_model"})
    if clash:
        raise UsageError(f"--set {clash[0]}: the load and the voltage model are what this command varies; give "
                         "them with --r-min/--r-max/--load and --models")
    return overrides


def _load_sweep(args) -> int:
    from . import load
    from .fmu import FmuRunError
    from .spec import check_times, prepare_output_dir

    model = _model(args)
    overrides = _circuit_overrides(model, args)
    models = _voltage_models(model, args, load.CIRCUIT_MODELS)
    r_min = _load_value(model, load.DEFAULT_R_MIN if args.r_min is None else args.r_min, "--r-min")
    r_max = _load_value(model, load.DEFAULT_R_MAX if args.r_max is None else args.r_max, "--r-max")
    if not r_min < r_max:
        raise UsageError(f"--r-min {r_min:g} is not below --r-max {r_max:g}: "
                         f"{'reversed' if r_min > r_max else 'empty'} range of R_load (give R_MIN < R_MAX, in Ohm)")
    count = load.DEFAULT_COUNT if args.count is None else args.count
    if count < 3:
        raise UsageError(f"--count {count}: need at least 3 loads to locate an optimum")
    stop_time, step = _times(args, DEFAULT_SWEEP_STEP)
    impact_step = load.IMPACT_STEP if args.impact_step is None else args.impact_step
    check_times(stop_time, impact_step)
    jobs = _jobs(args)
    out = prepare_output_dir(args.out)
    extremes = [{**overrides, "voltage_model": m, "R_load": r} for m in models for r in (r_min, r_max)]
    unzipdir, instance = _preflight(model, extremes, "load sweep")
    try:
        summary = load.run_load_sweep(model, out, unzipdir, instance, models, load.log_loads(r_min, r_max, count),
                                      stop_time, step, overrides, jobs)
        print("\n".join(load.summary_lines(summary)))
        if not args.no_impact:
            loads = {"paper's": float(model.parameters["R_load"].start), "optimum": load.best_load(summary)}
            loads = {label: r for label, r in loads.items() if r is not None}
            try:
                result = load.run_impacts(model, out, instance, loads, (0, *models), impact_step, overrides,
                                          stop_time)
            except FmuRunError as error:
                print(f"{PROG} load-sweep: no single-impact figures: {error}", file=sys.stderr)
            else:
                print("\n".join(load.impact_lines(result)))
    finally:
        load.cleanup(instance, unzipdir)
    return 0


def _impact_voltage(args) -> int:
    from . import load
    from .fmu import FmuRunError
    from .spec import prepare_output_dir

    model = _model(args)
    overrides = _circuit_overrides(model, args)
    models = _voltage_models(model, args, (0, *load.CIRCUIT_MODELS))
    given = [_load_value(model, value, "--load") for value in args.load]
    stop_time, step = _times(args, load.IMPACT_STEP)
    out = prepare_output_dir(args.out)
    nominal = float(model.parameters["R_load"].start)
    checked = given or [nominal]
    unzipdir, instance = _preflight(model, [{**overrides, "voltage_model": m, "R_load": r}
                                            for m in models for r in checked], "impact voltage")
    try:
        if given:
            loads = {load.ohm_text(r): r for r in given}
        else:
            estimate = load.circuit_constants(instance, overrides)["R_opt_estimate_ohm"]
            loads = {"paper's": nominal, "1/(omega_c C_p)": estimate}
        result = load.run_impacts(model, out, instance, loads, models, step, overrides, stop_time)
    except FmuRunError as error:
        raise UsageError(f"impact voltage (--stop-time {stop_time:g} s bounds the search for the first impact): "
                         f"{error}") from None
    finally:
        load.cleanup(instance, unzipdir)
    print("\n".join(load.impact_lines(result)))
    return 0


# -- frequency response ----------------------------------------------------------------------------

def _positive(value: float, option: str, what: str, unit: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"{option} {value:g}: {what} must be a finite number > 0; allowed range (0, inf) {unit}")
    return value


def _whole(value: int, option: str, lowest: int, what: str) -> int:
    if value < lowest:
        raise UsageError(f"{option} {value}: {what}; allowed range [{lowest}, inf)")
    return value


def _frequency_spec(args, model, instance, defaults: Optional[dict] = None, searched: tuple = ()):
    """The study the options ask for, checked (values, ranges, and the FMU's own checks);
    ``searched`` parameters (the optimiser's) are left out of the FMU's checks. ``defaults``: the
    band's (:data:`piezo_fmu_harness.frequency_response.BAND_DEFAULTS` unless given)."""
    from . import frequency_response as fr
    from .load import circuit_constants
    from .spec import check_with_fmu
    from .steady_state import STATE_PARAMETERS, Settings

    defaults = defaults or fr.BAND_DEFAULTS
    overrides = _assignments(model, args.set)
    for name in overrides:
        if name in STATE_PARAMETERS:
            raise UsageError(f"--set {name}: the initial state is what the shooting sets at each frequency; "
                             f"it cannot be set (the settable parameters exclude {', '.join(STATE_PARAMETERS)})")
        if name in ("R_load", "voltage_model"):
            raise UsageError(f"--set {name}: give the load and the voltage model with --load and --voltage-model")
    if args.acceleration is not None:
        amplitude, acceleration = None, _positive(args.acceleration, "--acceleration", "the base acceleration "
                                                  "amplitude A", "m/s^2")
    else:
        amplitude = _positive(fr.DEFAULT_AMPLITUDE if args.amplitude is None else args.amplitude, "--amplitude",
                              "the base displacement amplitude Y", "m")
        acceleration = None
    lo = _positive(defaults["ratios"][0] if args.ratio_min is None else args.ratio_min, "--ratio-min",
                   "the lowest frequency ratio w / sqrt(K/M)", "")
    hi = _positive(defaults["ratios"][1] if args.ratio_max is None else args.ratio_max, "--ratio-max",
                   "the highest frequency ratio w / sqrt(K/M)", "")
    count = _whole(defaults["count"] if args.count is None else args.count, "--count", defaults["fewest"],
                   f"need at least {defaults['fewest']} frequenc{'y' if defaults['fewest'] == 1 else 'ies'}")
    if count == 1 and lo != hi:
        raise UsageError(f"--count 1 needs --ratio-min = --ratio-max (one frequency); got {lo:g} and {hi:g}")
    if count > 1 and not lo < hi:
        raise UsageError(f"--ratio-min {lo:g} is not below --ratio-max {hi:g}: "
                         f"{'reversed' if lo > hi else 'empty'} range of frequencies (give RATIO_MIN < RATIO_MAX)")
    cap = defaults["max_cycles"]
    defaults = Settings()
    samples = _whole(defaults.samples if args.samples is None else args.samples, "--samples", 16,
                     "need at least 16 communication steps per forcing period")
    tolerance = defaults.tolerance if args.tolerance is None else args.tolerance
    if not (math.isfinite(tolerance) and 0 < tolerance <= 1e-2):
        raise UsageError(f"--tolerance {tolerance:g}: the steady-state tolerance (relative to Y) must lie in "
                         "(0, 0.01]")
    cycles = _whole(cap if args.max_cycles is None else args.max_cycles, "--max-cycles", 10,
                    "the cap on forcing cycles per frequency must be at least 10")
    newton = _whole(defaults.newton_iterations if args.newton_iterations is None else args.newton_iterations,
                    "--newton-iterations", 0, "the Newton iterations cannot be negative")
    parameter = model.parameters["voltage_model"]
    try:
        voltage_model = parameter.coerce(fr.DEFAULT_VOLTAGE_MODEL if args.voltage_model is None else args.voltage_model)
    except ValueError as error:
        raise UsageError(f"--voltage-model {args.voltage_model}: {error}") from None
    values = {**overrides, "voltage_model": voltage_model}
    if args.load is not None:
        values["R_load"] = _load_value(model, args.load, "--load")
    else:
        check_with_fmu(model, instance, [values], "--set")
        values["R_load"] = float(f"{circuit_constants(instance, values)['R_opt_estimate_ohm']:.6g}")
    checked = {name: value for name, value in values.items() if name not in searched}
    parameters = {**model.defaults(), **values}
    natural = math.sqrt(parameters["K"] / parameters["M"])
    ratios = tuple(float(f"{r:.12g}") for r in (np.linspace(lo, hi, count) if count > 1 else [lo]))
    peak_y = amplitude if amplitude is not None else acceleration / (lo * natural) ** 2
    peak = float(np.max(fr.linear_transmissibility(np.linspace(lo, hi, 4001) * natural, parameters["M"],
                                                   parameters["K"], parameters["C"])))
    spec = fr.FrequencySpec(ratios=ratios, natural=natural, amplitude=amplitude, acceleration=acceleration,
                            values=values, wide_gap=fr.wide_gap(peak_y, peak),
                            settings=Settings(samples=samples, tolerance=tolerance, max_cycles=cycles,
                                              newton_iterations=newton))
    check_with_fmu(model, instance, [{**checked, "d": spec.wide_gap} if damper == "without" else checked
                                     for damper in fr.DAMPER_CASES], "frequency response")
    return spec


def _frequency_response(args) -> int:
    from . import frequency_response as fr
    from .engine import InProcess

    model = _model(args)
    missing = [name for name in ("harvested_energy", "base_displacement") if name not in {**model.outputs, **model.inputs}]
    if missing:
        raise UsageError(f"--fmu {model.path}: the FMU lacks {', '.join(missing)}; rebuild it")
    jobs = _jobs(args)
    unzipdir, instance = _preflight(model, [{}], "--fmu")
    try:
        spec = _frequency_spec(args, model, instance)
        run = fr.open_frequency_run(model, spec, args.out, args.resume, args.force)
        remaining = run.total - len(run.done)
        warming = None
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            run.begin()
            if remaining:
                backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                           else _backend(args, model, unzipdir, min(jobs, len(fr.CHAINS))))
                print(f"{PROG} frequency-response: {remaining} of {run.total} points to run on {backend.description}",
                      file=sys.stderr)
                try:
                    warming = fr.execute(run, backend, progress=False if args.no_progress else None)
                except KeyboardInterrupt:
                    print(f"\n{PROG} frequency-response: interrupted; {len(run.done)} of {run.total} points are saved "
                          f"in {run.folder / 'points.jsonl'}; run the same command with --resume to finish",
                          file=sys.stderr)
                    return 130
        finally:
            signal.signal(signal.SIGTERM, previous)
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    result = fr.finish(model, run, jobs, warming)
    print("\n".join(fr.summary_lines(result["summary"])))
    print(f"  results in {run.folder}")
    return 0


# -- optimize --------------------------------------------------------------------------------------

def _search_bounds(model, texts: list[str], fixed: dict, forced: bool) -> tuple[tuple, tuple, tuple]:
    """``--param NAME=LO:HI`` as checked ``(names, lower, upper)``."""
    from .optimize import STATE
    from .spec import _checked, _lookup, _number, _split

    names, lower, upper = [], [], []
    for text in texts:
        name, rest = _split(text, "--param", "NAME=LO:HI")
        where = f"--param {text}"
        parameter = _lookup(model, name, where)
        if parameter.type != "Real":
            raise UsageError(f"{where}: {name} is an Integer parameter; the search is over Real parameters only "
                             "(fix it with --set)")
        if forced and name in STATE:
            raise UsageError(f"{where}: the initial state is what the shooting sets under the forced objective")
        if name in fixed:
            raise UsageError(f"{where}: {name} is both searched (--param) and fixed (--set); give one")
        if name in names:
            raise UsageError(f"{where}: {name} is given more than one --param")
        parts = rest.split(":")
        if len(parts) != 2:
            raise UsageError(f"{where}: expected NAME=LO:HI, e.g. m=0.02:0.2")
        lo, hi = (_checked(parameter, _number(part, where), where) for part in parts)
        if not lo < hi:
            raise UsageError(f"{where}: {'reversed' if lo > hi else 'empty'} range for {name}: LO = {lo:g} must be "
                             f"below HI = {hi:g}")
        names.append(name)
        lower.append(float(lo))
        upper.append(float(hi))
    if not names:
        raise UsageError("--param NAME=LO:HI is required: the parameters to search and their bounds")
    return tuple(names), tuple(lower), tuple(upper)


def _terms_option(texts: list[str], option: str, allowed: tuple, positive: bool) -> dict:
    """``TERM=VALUE`` pairs of ``--weight`` or ``--reference``, checked."""
    from .spec import _number, _split

    values = {}
    for text in texts:
        name, rest = _split(text, option, "TERM=VALUE")
        if name not in allowed:
            raise UsageError(f"{option} {text}: unknown term {name!r}; allowed: {', '.join(allowed)}")
        value = _number(rest, f"{option} {text}")
        if positive and not value > 0:
            raise UsageError(f"{option} {text}: a reference value must be > 0; allowed range (0, inf)")
        values[name] = value
    return values


def _optimize(args) -> int:
    from . import optimize as opt
    from .engine import InProcess
    from .spec import check_with_fmu, check_times

    model = _model(args)
    forced = args.objective == "forced"
    jobs = _jobs(args)
    fixed = _assignments(model, args.set)
    names, lower, upper = _search_bounds(model, args.param, fixed, forced)
    weights = {**opt.DEFAULT_WEIGHTS[args.objective],
               **_terms_option(args.weight, "--weight", tuple(opt.TERMS[args.objective]), positive=False)}
    if not any(weights.values()):
        raise UsageError(f"--weight: every weight is 0 ({', '.join(f'{k}={v:g}' for k, v in weights.items())}); "
                         "nothing to optimise")
    references = _terms_option(args.reference, "--reference", opt.REFERENCES[args.objective], positive=True)
    search = opt.SEARCH_DEFAULTS[args.objective]
    settings = {key: getattr(args, key) if getattr(args, key) is not None else default
                for key, default in search.items()}
    for key, lowest in (("maxiter", 1), ("popsize", 1)):
        _whole(settings[key], f"--{key}", lowest, f"need at least {lowest}")
    if not (math.isfinite(settings["tol"]) and settings["tol"] > 0):
        raise UsageError(f"--tol {settings['tol']:g}: the tolerance must be a finite number > 0; allowed range (0, inf)")
    if not 0 < settings["sensitivity_step"] <= 0.5:
        raise UsageError(f"--sensitivity-step {settings['sensitivity_step']:g}: a fraction of each range; allowed "
                         "range (0, 0.5]")
    settings.update(polish=args.polish, grid=not args.no_grid)
    if args.damping == "ls" and "damping_inclination_ls" not in model.outputs:
        raise UsageError(f"--damping ls: the FMU {model.path} lacks the output damping_inclination_ls; rebuild it")
    stop_time, step = _times(args, DEFAULT_SWEEP_STEP)
    check_times(stop_time, step)
    unzipdir, instance = _preflight(model, [fixed], "--set")
    backend = None
    try:
        band, values = None, fixed
        if forced:
            band = _frequency_spec(args, model, instance, opt.BAND_DEFAULTS, names)
            values = band.values
        parameters = {**model.defaults(), **values}
        problem = opt.Problem(names=names, lower=lower, upper=upper, objective=args.objective, weights=weights,
                              fixed=dict(values), stop_time=stop_time, step=step,
                              damping="DI_ls" if args.damping == "ls" else "DI", band=band,
                              without_each_time=forced and bool(set(names) & {"M", "K", "C"}))
        corners = [problem.values(corner) for corner in _box_corners(lower, upper)]
        check_with_fmu(model, instance, corners, "the bounds of --param")
        folder, cache = opt.open_optimization(model, problem, references, args.out, args.resume, args.force, settings)
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else _backend(args, model, unzipdir, jobs))
        print(f"{PROG} optimize: {args.objective} objective over {', '.join(names)} on {backend.description}"
              + (f" ({len(cache)} evaluations already recorded)" if cache else ""), file=sys.stderr)
        optimizer = opt.Optimizer(problem, backend, folder, references=dict(references), cache=cache)
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            report = opt.run(optimizer, [parameters[name] for name in names], settings["maxiter"],
                             settings["popsize"], settings["seed"], settings["polish"], settings["tol"],
                             settings["grid"], settings["sensitivity_step"])
        except KeyboardInterrupt:
            print(f"\n{PROG} optimize: interrupted; every evaluation so far is in {folder / opt.EVALUATIONS_FILE}; "
                  "run the same command with --resume to go on", file=sys.stderr)
            return 130
        except ValueError as error:
            raise UsageError(str(error)) from None
        finally:
            signal.signal(signal.SIGTERM, previous)
    finally:
        if backend is not None and not isinstance(backend, InProcess):
            backend.close()
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    opt.write_report(report, problem, folder, model)
    print("\n".join(opt.report_lines(report, problem, model)))
    print(f"  results in {folder}")
    return 0


def _box_corners(lower: tuple, upper: tuple) -> list[tuple]:
    """The corners of the search box (all of them up to 6 parameters, else the two extremes)."""
    import itertools

    if len(lower) <= 6:
        return list(itertools.product(*zip(lower, upper)))
    return [tuple(lower), tuple(upper)]


# -- sweep -----------------------------------------------------------------------------------------

def _sweep_specs(args, model) -> tuple[list[tuple[str, object, Path]], Optional[dict], Path]:
    """The sweeps asked for: ``[(name, spec, folder)]``, the panels of a preset set, and OUT."""
    from .spec import build_spec, load_toml, parse_grid

    sources = [bool(args.preset), bool(args.config)]
    if sum(sources) > 1:
        raise UsageError("give either --preset or --config, not both")
    config = load_toml(model, args.config) if args.config else {}
    stop_time, step = _times(args, DEFAULT_SWEEP_STEP, config)
    cli_axes = [parse_grid(model, text) for text in args.grid]
    cli_fixed = _assignments(model, args.set)

    if args.preset in presets.PRESET_SETS:
        panels = presets.PRESET_SETS[args.preset]["panels"]
        names = list(panels.values())
    elif args.preset:
        panels, names = None, [args.preset]
    else:
        panels, names = None, [None]
    out = args.out or (Path(config["out"]) if "out" in config else None)
    if out is None:
        out = Path("results") / (args.preset or "sweep")

    sweeps = []
    for name in names:
        if name is None:
            axes, fixed = list(config.get("axes", [])), dict(config.get("fixed", {}))
        else:
            preset = presets.PRESETS[name]
            axes = [parse_grid(model, text) for text in preset["grid"]]
            fixed = _assignments(model, preset["set"])
        by_name = {axis.name: axis for axis in axes}
        for axis in cli_axes:
            by_name[axis.name] = axis
            fixed.pop(axis.name, None)
        fixed.update(cli_fixed)
        spec = build_spec(list(by_name.values()), fixed, stop_time, step,
                          name or config.get("name") or Path(out).name)
        folder = Path(out) / name if panels else Path(out)
        sweeps.append((name or spec.name, spec, folder))
    return sweeps, panels, Path(out)


def _jobs(args) -> int:
    from .engine import default_jobs

    jobs = args.jobs if args.jobs is not None else default_jobs()
    if jobs < 1:
        raise UsageError(f"--jobs {jobs}: need at least 1 worker")
    return jobs


def _backend(args, model, unzipdir: str, jobs: int):
    """The engine's backend the options ask for: a Dask cluster, or a pool of ``jobs`` processes."""
    from .engine import DaskCluster, ProcessPool

    if args.scheduler or args.dask_local:
        try:
            return DaskCluster(model, args.scheduler, jobs)
        except (OSError, TimeoutError) as error:
            raise UsageError(f"--scheduler {args.scheduler}: cannot reach the Dask scheduler ({error})") from None
    return ProcessPool(model, unzipdir, jobs)


def _sweep(args) -> int:
    from . import analysis
    from .sweep import display, execute, open_sweep, write_results

    model = _model(args)
    sweeps, panels, out = _sweep_specs(args, model)
    jobs = _jobs(args)
    quantile = analysis.DEFAULT_ZONE_QUANTILE if args.zone_quantile is None else args.zone_quantile
    if not 0.0 < quantile < 1.0:
        raise UsageError(f"--zone-quantile {quantile:g}: must lie between 0 and 1")
    if args.damping == "ls" and "damping_inclination_ls" not in model.outputs:
        raise UsageError(f"--damping ls: the FMU {model.path} lacks the output damping_inclination_ls (an FMU "
                         "built before it); rebuild it, or rank by eq. 29 (--damping eq29)")

    runs = [open_sweep(model, spec, folder, args.resume, args.force) for _, spec, folder in sweeps]
    corners = [spec.values_at(c) for _, spec, _ in sweeps for c in _corners(spec)]
    unzipdir, instance = _preflight(model, corners, "sweep grid")
    instance.free()

    remaining = sum(len(run.todo()) for run in runs)
    warming = None
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        if remaining:
            backend = _backend(args, model, unzipdir, min(jobs, remaining))
        for run in runs:
            run.begin()
        if remaining:
            total = sum(run.spec.size for run in runs)
            print(f"{PROG} sweep: {remaining} of {total} points to run on {backend.description} "
                  f"({runs[0].spec.stop_time:g} s each, communication step {runs[0].spec.step:g} s)",
                  file=sys.stderr)
            try:
                warming = execute(runs, backend, progress=False if args.no_progress else None)
            except KeyboardInterrupt:
                finished = sum(len(run.done) for run in runs)
                print(f"\n{PROG} sweep: interrupted; {finished} of {total} points are saved in "
                      f"{', '.join(str(run.store.path) for run in runs)}; run the same command with "
                      "--resume to finish", file=sys.stderr)
                return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        shutil.rmtree(unzipdir, ignore_errors=True)

    names = [name for name, _, _ in sweeps]
    results = write_results(model, runs, names, panels, out, quantile, args.damping, jobs, warming=warming)
    for name, run in zip(names, runs):
        print("\n".join(analysis.zone_summary_lines(results[name]["zones"], display(results[name]["dataset"]))))
        failed = int((results[name]["dataset"]["status"] == "error").sum())
        if failed:
            print(f"  {failed} points were rejected by the FMU (status 'error' in {run.folder / 'sweep.csv'})")
        print(f"  results in {run.folder}")
    if panels:
        print(f"Figs. 4-9 in {out}")
    return 0


def _corners(spec) -> list[dict]:
    """The grid corners the FMU checks first (all of them up to 6 axes, else the two extremes)."""
    if len(spec.axes) <= 6:
        return list(spec.corners())
    return [{a.name: a.values[0] for a in spec.axes}, {a.name: a.values[-1] for a in spec.axes}]


def _interrupt(signum, frame):
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(main())
