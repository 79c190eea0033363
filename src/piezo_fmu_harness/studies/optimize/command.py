"""The optimiser on the command line: ``piezo-fmu optimize``."""

from __future__ import annotations

import math
import signal
import sys

from ...fmu import discard
from ...checks import (
    PROG,
    assignments,
    interrupt,
    make_backend,
    open_model,
    preflight,
    times,
    whole,
    worker_count,
)
from ...spec import DEFAULT_SWEEP_STEP, UsageError
from ...wording import counted


#: Why an objective cannot search the initial state.
STATE_SET_BY = {"forced": "what the shooting sets under the forced objective",
                "random": "rest for every realization under the random objective"}


def search_bounds(model, texts: list[str], fixed: dict, objective: str) -> tuple[tuple, tuple, tuple]:
    """``--param NAME=LO:HI`` as checked ``(names, lower, upper)``."""
    from ...spec import _checked, _lookup, _number, _split
    from .search import STATE

    names, lower, upper = [], [], []
    for text in texts:
        name, rest = _split(text, "--param", "NAME=LO:HI")
        where = f"--param {text}"
        parameter = _lookup(model, name, where)
        if parameter.type != "Real":
            raise UsageError(f"{where}: {name} is an Integer parameter; the search is over Real parameters only "
                             "(fix it with --set)")
        if objective in STATE_SET_BY and name in STATE:
            raise UsageError(f"{where}: the initial state is {STATE_SET_BY[objective]}; it cannot be searched")
        if name in fixed:
            raise UsageError(f"{where}: {name} is both searched (--param) and fixed (--set); give one")
        if name in names:
            raise UsageError(f"{where}: {name} is given more than one --param")
        parts = rest.split(":")
        if len(parts) != 2:
            raise UsageError(f"{where}: expected NAME=LO:HI, e.g. m=0.02:0.2")
        lo, hi = (_checked(parameter, _number(part, where), where) for part in parts)
        if objective == "random" and name == "C" and not lo > 0:
            raise UsageError(f"{where}: without damping the main mass's response to a stationary input never settles; "
                             "allowed range (0, inf) N.s/m")
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
    from ...spec import _number, _split

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
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from ...spec import check_times, check_with_fmu
    from . import report as optimize_report
    from . import search as opt
    from .log import open_optimization

    model = open_model(args)
    forced = args.objective == "forced"
    jobs = worker_count(args)
    fixed = assignments(model, args.set)
    names, lower, upper = search_bounds(model, args.param, fixed, args.objective)
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
    settings.update(polish=args.polish, grid=not args.no_grid, seed=whole(args.seed, "--seed", 0,
                                                                          "the seed is a whole number >= 0"))
    if args.damping == "ls" and "damping_inclination_ls" not in model.outputs:
        raise UsageError(f"--damping ls: the FMU {model.path} lacks the output damping_inclination_ls; rebuild it")
    stop_time, step = times(args, DEFAULT_SWEEP_STEP)
    check_times(stop_time, step)
    unzipdir, instance = preflight(model, [fixed], "--set")
    backend = None
    try:
        band, values, spectrum = None, fixed, None
        if forced:
            band = frequency_spec(args, model, instance, opt.BAND_DEFAULTS, names)
            values = band.values
        elif args.objective == "random":
            values, spectrum = random_spec(args, model, instance, fixed, names, lower, upper)
        parameters = {**model.defaults(), **values}
        problem = opt.Problem(names=names, lower=lower, upper=upper, objective=args.objective, weights=weights,
                              fixed=dict(values), stop_time=stop_time, step=step,
                              damping="DI_ls" if args.damping == "ls" else "DI", band=band,
                              without_each_time=forced and bool(set(names) & {"M", "K", "C"}), random=spectrum)
        corners = [problem.values(corner) for corner in box_corners(lower, upper)]
        check_with_fmu(model, instance, corners, "the bounds of --param")
        folder, cache = open_optimization(model, problem, references, args.out, args.resume, args.force, settings)
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, jobs))
        print(f"{PROG} optimize: {args.objective} objective over {', '.join(names)} on {backend.description}"
              + (f" ({len(cache)} evaluations already recorded)" if cache else ""), file=sys.stderr)
        if spectrum:
            print(f"{PROG} optimize: each design marched on {counted(spectrum['realizations'], 'realization')} "
                  f"(seed {spectrum['seed']}, the same for every design) of {spectrum['warmup']:.3g} s of warm-up + "
                  f"{spectrum['duration']:.3g} s, with and without the damper, on the batch engine", file=sys.stderr)
        from tqdm import tqdm

        optimizer = opt.Optimizer(problem, backend, folder, references=dict(references), cache=cache,
                                  bar=tqdm(unit="evaluation", desc="optimize", dynamic_ncols=True, file=sys.stderr,
                                           disable=True if args.no_progress else None))
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
            optimizer.bar.close()
            signal.signal(signal.SIGTERM, previous)
    finally:
        if backend is not None and not isinstance(backend, InProcess):
            backend.close()
        instance.free()
        discard(unzipdir)
    optimize_report.write_report(report, problem, folder, model)
    print("\n".join(optimize_report.report_lines(report, problem, model)))
    print(f"  results in {folder}")
    return 0


def random_spec(args, model, instance, fixed: dict, names: tuple, lower: tuple, upper: tuple) -> tuple[dict, dict]:
    """Under ``--objective random``: the reference design's parameters (from rest, the voltage
    model and the load) and the excitation's spec (a dict), whose warm-up by default is the longest
    any design within the bounds needs (the largest ``M``, the smallest ``C``)."""
    from ...random_response.arguments import damper_values, excitation_spec

    values = damper_values(args, model, instance, fixed)
    bounds = {name: (lo, hi) for name, lo, hi in zip(names, lower, upper)}
    slowest = {**values, **{name: bounds[name][side] for name, side in (("M", 1), ("C", 0)) if name in bounds}}
    return values, excitation_spec(args, values, "optimize", slowest).to_dict()


def box_corners(lower: tuple, upper: tuple) -> list[tuple]:
    """The corners of the search box (all of them up to 6 parameters, else the two extremes)."""
    import itertools

    if len(lower) <= 6:
        return list(itertools.product(*zip(lower, upper)))
    return [tuple(lower), tuple(upper)]
