"""``piezo-fmu``: the nominal case, sweeps and the two designs, all through the FMU with fmpy.

    piezo-fmu nominal [--out DIR] [--stop-time S] [--step S] [--set NAME=VALUE ...]
    piezo-fmu sweep (--grid NAME=START:STOP:COUNT ... | --preset NAME | --config FILE.toml)
                    [--set NAME=VALUE ...] [--stop-time S] [--step S] [--out DIR] [--jobs N]
                    [--scheduler ADDRESS | --dask-local] [--resume | --force]
    piezo-fmu two-designs [--out DIR] [--stop-time S] [--step S]
    piezo-fmu load-sweep [--r-min OHM] [--r-max OHM] [--count N] [--models 1,2] [--set NAME=VALUE ...]
                         [--stop-time S] [--step S] [--impact-step S] [--out DIR] [--jobs N]
    piezo-fmu impact-voltage [--load OHM ...] [--models 0,1,2] [--step S] [--set NAME=VALUE ...] [--out DIR]
    piezo-fmu presets

Values are SI (m, kg, s, V). Bad input (an unknown parameter, an empty or reversed range, a
value outside the bounds of the FMU's modelDescription, an unwritable output folder) is
reported before anything runs, with exit status 2. An interrupted sweep exits with 130 and
keeps every finished point; run the same command with ``--resume`` to finish it.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import sys
from pathlib import Path
from typing import Optional

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
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def common(sub, step_default: float, step_help: str) -> None:
        sub.add_argument("--stop-time", type=float, default=None, metavar="S",
                         help=f"duration simulated, s (default {DEFAULT_STOP_TIME:g})")
        sub.add_argument("--step", type=float, default=None, metavar="S",
                         help=f"communication step, s (default {step_default:g}; {step_help})")
        sub.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                         help="set an FMU parameter (SI), repeatable")
        sub.add_argument("--fmu", type=Path, default=None,
                         help="the FMU (default $PIEZO_FMU or fmus/PiezoImpactDamper.fmu)")

    def results_folder(sub, name: str) -> None:
        sub.add_argument("--out", type=Path, default=Path("results") / name, metavar="DIR",
                         help=f"results folder (default results/{name})")

    def jobs(sub) -> None:
        sub.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")

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
                       help="results folder (default results/PRESET for a preset)")
    jobs(sweep)
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
    where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")
    again = sweep.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true",
                       help="finish the sweep in --out: run only the points not yet recorded")
    again.add_argument("--force", action="store_true", help="start over, discarding the points in --out")
    sweep.add_argument("--zone-quantile", type=float, default=None, metavar="Q",
                       help="our zones are the points at or above this quantile of each metric (default 0.9)")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")

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
                "impact-voltage": _impact_voltage}[args.command](args)
    except UsageError as error:
        print(f"{PROG} {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


# -- shared steps ----------------------------------------------------------------------------------

def _model(args):
    from .fmu import FmuModel, default_fmu_path

    path = args.fmu or default_fmu_path()
    try:
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
    from .engine import default_jobs
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
    jobs = args.jobs if args.jobs is not None else default_jobs()
    if jobs < 1:
        raise UsageError(f"--jobs {jobs}: need at least 1 worker")
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
        if not args.preset:
            raise UsageError("--out DIR is required (the folder for the sweep's results)")
        out = Path("results") / args.preset

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


def _sweep(args) -> int:
    from . import analysis
    from .engine import DaskCluster, ProcessPool, default_jobs
    from .sweep import display, execute, finish, open_sweep

    model = _model(args)
    sweeps, panels, out = _sweep_specs(args, model)
    jobs = args.jobs if args.jobs is not None else default_jobs()
    if jobs < 1:
        raise UsageError(f"--jobs {jobs}: need at least 1 worker")
    quantile = analysis.DEFAULT_ZONE_QUANTILE if args.zone_quantile is None else args.zone_quantile
    if not 0.0 < quantile < 1.0:
        raise UsageError(f"--zone-quantile {quantile:g}: must lie between 0 and 1")

    runs = [open_sweep(model, spec, folder, args.resume, args.force) for _, spec, folder in sweeps]
    corners = [spec.values_at(c) for _, spec, _ in sweeps for c in _corners(spec)]
    unzipdir, instance = _preflight(model, corners, "sweep grid")
    instance.free()

    remaining = sum(len(run.todo()) for run in runs)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        if remaining:
            if args.scheduler or args.dask_local:
                try:
                    backend = DaskCluster(model, args.scheduler, jobs)
                except (OSError, TimeoutError) as error:
                    raise UsageError(f"--scheduler {args.scheduler}: cannot reach the Dask scheduler ({error})") from None
            else:
                backend = ProcessPool(model, unzipdir, min(jobs, remaining))
        for run in runs:
            run.begin()
        if remaining:
            total = sum(run.spec.size for run in runs)
            print(f"{PROG} sweep: {remaining} of {total} points to run on {backend.description} "
                  f"({runs[0].spec.stop_time:g} s each, communication step {runs[0].spec.step:g} s)",
                  file=sys.stderr)
            try:
                execute(runs, backend, progress=False if args.no_progress else None)
            except KeyboardInterrupt:
                finished = sum(len(run.done) for run in runs)
                print(f"\n{PROG} sweep: interrupted; {finished} of {total} points are saved in "
                      f"{', '.join(str(run.store.path) for run in runs)}; run the same command with "
                      "--resume to finish", file=sys.stderr)
                return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        shutil.rmtree(unzipdir, ignore_errors=True)

    results = {}
    for (name, _, _), run in zip(sweeps, runs):
        results[name] = finish(model, run, quantile)
        print("\n".join(analysis.zone_summary_lines(results[name]["zones"], display(results[name]["dataset"]))))
        failed = int((results[name]["dataset"]["status"] == "error").sum())
        if failed:
            print(f"  {failed} points were rejected by the FMU (status 'error' in {run.folder / 'sweep.csv'})")
        print(f"  results in {run.folder}")
    if panels:
        from . import figures

        figures.paper_figures({letter: (results[name]["dataset"], results[name]["masks"], results[name]["paper_zone"])
                               for letter, name in panels.items()}, out)
        combined = {name: results[name]["zones"] for name in panels.values()}
        (out / "zones.json").write_text(json.dumps(combined, indent=2) + "\n")
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
