"""The forced response on the command line: ``piezo-fmu frequency-response`` and ``optimize``."""

from __future__ import annotations

import math
import shutil
import signal
import sys
from typing import Optional

import numpy as np

from .checks import (
    PROG,
    assignments,
    interrupt,
    load_value,
    make_backend,
    open_model,
    positive,
    preflight,
    times,
    whole,
    worker_count,
)
from .spec import DEFAULT_SWEEP_STEP, UsageError


def frequency_spec(args, model, instance, defaults: Optional[dict] = None, searched: tuple = ()):
    """The study the options ask for, checked (values, ranges, and the FMU's own checks);
    ``searched`` parameters (the optimiser's) are left out of the FMU's checks. ``defaults``: the
    band's (:data:`piezo_fmu_harness.frequency_response.BAND_DEFAULTS` unless given)."""
    from . import frequency_response as fr
    from .drive import STATE_PARAMETERS
    from .load import circuit_constants
    from .spec import check_with_fmu
    from .steady_state import Settings

    defaults = defaults or fr.BAND_DEFAULTS
    overrides = assignments(model, args.set)
    for name in overrides:
        if name in STATE_PARAMETERS:
            raise UsageError(f"--set {name}: the initial state is what the shooting sets at each frequency; "
                             f"it cannot be set (the settable parameters exclude {', '.join(STATE_PARAMETERS)})")
        if name in ("R_load", "voltage_model"):
            raise UsageError(f"--set {name}: give the load and the voltage model with --load and --voltage-model")
    if args.acceleration is not None:
        amplitude, acceleration = None, positive(args.acceleration, "--acceleration", "the base acceleration "
                                                  "amplitude A", "m/s^2")
    else:
        amplitude = positive(fr.DEFAULT_AMPLITUDE if args.amplitude is None else args.amplitude, "--amplitude",
                              "the base displacement amplitude Y", "m")
        acceleration = None
    lo = positive(defaults["ratios"][0] if args.ratio_min is None else args.ratio_min, "--ratio-min",
                   "the lowest frequency ratio w / sqrt(K/M)", "")
    hi = positive(defaults["ratios"][1] if args.ratio_max is None else args.ratio_max, "--ratio-max",
                   "the highest frequency ratio w / sqrt(K/M)", "")
    count = whole(defaults["count"] if args.count is None else args.count, "--count", defaults["fewest"],
                   f"need at least {defaults['fewest']} frequenc{'y' if defaults['fewest'] == 1 else 'ies'}")
    if count == 1 and lo != hi:
        raise UsageError(f"--count 1 needs --ratio-min = --ratio-max (one frequency); got {lo:g} and {hi:g}")
    if count > 1 and not lo < hi:
        raise UsageError(f"--ratio-min {lo:g} is not below --ratio-max {hi:g}: "
                         f"{'reversed' if lo > hi else 'empty'} range of frequencies (give RATIO_MIN < RATIO_MAX)")
    cap = defaults["max_cycles"]
    defaults = Settings()
    samples = whole(defaults.samples if args.samples is None else args.samples, "--samples", 16,
                     "need at least 16 communication steps per forcing period")
    tolerance = defaults.tolerance if args.tolerance is None else args.tolerance
    if not (math.isfinite(tolerance) and 0 < tolerance <= 1e-2):
        raise UsageError(f"--tolerance {tolerance:g}: the steady-state tolerance (relative to Y) must lie in "
                         "(0, 0.01]")
    cycles = whole(cap if args.max_cycles is None else args.max_cycles, "--max-cycles", 10,
                    "the cap on forcing cycles per frequency must be at least 10")
    newton = whole(defaults.newton_iterations if args.newton_iterations is None else args.newton_iterations,
                    "--newton-iterations", 0, "the Newton iterations cannot be negative")
    parameter = model.parameters["voltage_model"]
    try:
        voltage_model = parameter.coerce(fr.DEFAULT_VOLTAGE_MODEL if args.voltage_model is None else args.voltage_model)
    except ValueError as error:
        raise UsageError(f"--voltage-model {args.voltage_model}: {error}") from None
    values = {**overrides, "voltage_model": voltage_model}
    if args.load is not None:
        values["R_load"] = load_value(model, args.load, "--load")
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


def frequency_response(args) -> int:
    from . import frequency_response as fr
    from . import frequency_results
    from .engine import InProcess

    model = open_model(args)
    missing = [name for name in ("harvested_energy", "base_displacement") if name not in {**model.outputs, **model.inputs}]
    if missing:
        raise UsageError(f"--fmu {model.path}: the FMU lacks {', '.join(missing)}; rebuild it")
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        spec = frequency_spec(args, model, instance)
        run = fr.open_frequency_run(model, spec, args.out, args.resume, args.force)
        remaining = run.total - len(run.done)
        previous = signal.signal(signal.SIGTERM, interrupt)
        try:
            run.begin()
            if remaining:
                backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                           else make_backend(args, model, unzipdir, min(jobs, len(fr.CHAINS))))
                print(f"{PROG} frequency-response: {remaining} of {run.total} points to run on {backend.description}",
                      file=sys.stderr)
                try:
                    fr.execute(run, backend, progress=False if args.no_progress else None)
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
    result = frequency_results.finish(model, run, jobs)
    print("\n".join(frequency_results.summary_lines(result["summary"])))
    print(f"  results in {run.folder}")
    return 0


def search_bounds(model, texts: list[str], fixed: dict, forced: bool) -> tuple[tuple, tuple, tuple]:
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


def terms_option(texts: list[str], option: str, allowed: tuple, positive: bool) -> dict:
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


def optimize(args) -> int:
    from . import optimize as opt
    from . import optimize_report
    from .engine import InProcess
    from .spec import check_times, check_with_fmu

    model = open_model(args)
    forced = args.objective == "forced"
    jobs = worker_count(args)
    fixed = assignments(model, args.set)
    names, lower, upper = search_bounds(model, args.param, fixed, forced)
    weights = {**opt.DEFAULT_WEIGHTS[args.objective],
               **terms_option(args.weight, "--weight", tuple(opt.TERMS[args.objective]), positive=False)}
    if not any(weights.values()):
        raise UsageError(f"--weight: every weight is 0 ({', '.join(f'{k}={v:g}' for k, v in weights.items())}); "
                         "nothing to optimise")
    references = terms_option(args.reference, "--reference", opt.REFERENCES[args.objective], positive=True)
    search = opt.SEARCH_DEFAULTS[args.objective]
    settings = {key: getattr(args, key) if getattr(args, key) is not None else default
                for key, default in search.items()}
    for key, lowest in (("maxiter", 1), ("popsize", 1)):
        whole(settings[key], f"--{key}", lowest, f"need at least {lowest}")
    if not (math.isfinite(settings["tol"]) and settings["tol"] > 0):
        raise UsageError(f"--tol {settings['tol']:g}: the tolerance must be a finite number > 0; allowed range (0, inf)")
    if not 0 < settings["sensitivity_step"] <= 0.5:
        raise UsageError(f"--sensitivity-step {settings['sensitivity_step']:g}: a fraction of each range; allowed "
                         "range (0, 0.5]")
    settings.update(polish=args.polish, grid=not args.no_grid)
    if args.damping == "ls" and "damping_inclination_ls" not in model.outputs:
        raise UsageError(f"--damping ls: the FMU {model.path} lacks the output damping_inclination_ls; rebuild it")
    stop_time, step = times(args, DEFAULT_SWEEP_STEP)
    check_times(stop_time, step)
    unzipdir, instance = preflight(model, [fixed], "--set")
    backend = None
    try:
        band, values = None, fixed
        if forced:
            band = frequency_spec(args, model, instance, opt.BAND_DEFAULTS, names)
            values = band.values
        parameters = {**model.defaults(), **values}
        problem = opt.Problem(names=names, lower=lower, upper=upper, objective=args.objective, weights=weights,
                              fixed=dict(values), stop_time=stop_time, step=step,
                              damping="DI_ls" if args.damping == "ls" else "DI", band=band,
                              without_each_time=forced and bool(set(names) & {"M", "K", "C"}))
        corners = [problem.values(corner) for corner in box_corners(lower, upper)]
        check_with_fmu(model, instance, corners, "the bounds of --param")
        folder, cache = opt.open_optimization(model, problem, references, args.out, args.resume, args.force, settings)
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, jobs))
        print(f"{PROG} optimize: {args.objective} objective over {', '.join(names)} on {backend.description}"
              + (f" ({len(cache)} evaluations already recorded)" if cache else ""), file=sys.stderr)
        optimizer = opt.Optimizer(problem, backend, folder, references=dict(references), cache=cache)
        previous = signal.signal(signal.SIGTERM, interrupt)
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
    optimize_report.write_report(report, problem, folder, model)
    print("\n".join(optimize_report.report_lines(report, problem, model)))
    print(f"  results in {folder}")
    return 0


def box_corners(lower: tuple, upper: tuple) -> list[tuple]:
    """The corners of the search box (all of them up to 6 parameters, else the two extremes)."""
    import itertools

    if len(lower) <= 6:
        return list(itertools.product(*zip(lower, upper)))
    return [tuple(lower), tuple(upper)]
