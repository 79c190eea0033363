"""The load on the command line: ``piezo-fmu load-sweep`` and ``impact-voltage``."""

from __future__ import annotations

import sys

from ...checks import (
    PROG,
    assignments,
    load_value,
    open_model,
    preflight,
    times,
    whole,
    worker_count,
)
from ...spec import DEFAULT_SWEEP_STEP, UsageError
from ...wording import counted


def voltage_models(model, args, allowed: tuple) -> tuple[int, ...]:
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


def circuit_overrides(model, args) -> dict:
    """``--set`` for the load commands; also checks the FMU declares what they read."""
    from ...circuit import CONSTANTS
    from ...fmu import ENERGY_OUTPUTS

    missing = ([n for n in ENERGY_OUTPUTS if n not in model.outputs]
               + [n for n in CONSTANTS if n not in model.calculated])
    if missing:
        raise UsageError(f"--fmu {model.path}: the FMU lacks {', '.join(missing)} (an FMU older than the circuit "
                         "voltage models' harvested energy outputs); rebuild it")
    overrides = assignments(model, args.set)
    clash = sorted(set(overrides) & {"R_load", "voltage_model"})
    if clash:
        raise UsageError(f"--set {clash[0]}: the load and the voltage model are what this command varies; give "
                         "them with --r-min/--r-max/--load and --models")
    return overrides


def load_sweep(args) -> int:
    import signal
    import time

    from ...checks import interrupt, make_backend
    from ...engine import InProcess
    from ...fmu import FmuRunError
    from ...spec import check_times
    from . import impacts, points
    from . import sweep as load

    model = open_model(args)
    overrides = circuit_overrides(model, args)
    models = voltage_models(model, args, load.CIRCUIT_MODELS)
    r_min = load_value(model, load.DEFAULT_R_MIN if args.r_min is None else args.r_min, "--r-min")
    r_max = load_value(model, load.DEFAULT_R_MAX if args.r_max is None else args.r_max, "--r-max")
    if not r_min < r_max:
        raise UsageError(f"--r-min {r_min:g} is not below --r-max {r_max:g}: "
                         f"{'reversed' if r_min > r_max else 'empty'} range of R_load (give R_MIN < R_MAX, in Ohm)")
    count = load.DEFAULT_COUNT if args.count is None else args.count
    whole(count, "--count", 3, "need at least 3 loads to locate an optimum")
    stop_time, step = times(args, DEFAULT_SWEEP_STEP)
    impact_step = impacts.IMPACT_STEP if args.impact_step is None else args.impact_step
    check_times(stop_time, impact_step)
    jobs = worker_count(args)
    loads = load.log_loads(r_min, r_max, count)
    nominal = float(model.parameters["R_load"].start)
    todo = points.points(models, loads, nominal, overrides)
    header = {"models": list(models), "loads_ohm": list(loads), "nominal_load_ohm": nominal, "stop_time": stop_time,
              "step": step, "overrides": overrides}
    folder, done, start_over = points.open_loads(model, header, args.out, todo, args.resume, args.force)
    extremes = [{**overrides, "voltage_model": m, "R_load": r} for m in models for r in (r_min, r_max)]
    unzipdir, instance = preflight(model, extremes, "load sweep")
    try:
        remaining = len(todo) - len(done)
        backend = (InProcess(instance) if min(jobs, remaining) <= 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, min(jobs, max(1, remaining))))
        print(f"{PROG} load-sweep: {remaining} of {counted(len(todo), 'point')} to run on {backend.description}", file=sys.stderr)
        begin = time.perf_counter()
        previous = signal.signal(signal.SIGTERM, interrupt)
        try:
            points.execute(backend, todo, folder, done, start_over, {**header, "fmu_guid": model.guid}, stop_time,
                           step, False if args.no_progress else None)
        except KeyboardInterrupt:
            print(f"\n{PROG} load-sweep: interrupted; {len(done)} of {counted(len(todo), 'point')} are saved in "
                  f"{folder / 'points.jsonl'}; run the same command with --resume to finish", file=sys.stderr)
            return 130
        finally:
            signal.signal(signal.SIGTERM, previous)
        summary = load.write_load_sweep(model, folder, instance, done, models, loads, stop_time, step, overrides,
                                        time.perf_counter() - begin, backend.description)
        print("\n".join(load.summary_lines(summary)))
        if not args.no_impact:
            loads = {"paper's": nominal, "optimum": load.best_load(summary)}
            loads = {label: r for label, r in loads.items() if r is not None}
            try:
                result = impacts.run_impacts(model, folder, instance, loads, (0, *models), impact_step, overrides,
                                             stop_time)
            except FmuRunError as error:
                print(f"{PROG} load-sweep: no single-impact figures: {error}", file=sys.stderr)
            else:
                print("\n".join(impacts.impact_lines(result)))
    finally:
        load.cleanup(instance, unzipdir)
    return 0


def impact_voltage(args) -> int:
    from ...fmu import FmuRunError
    from ...store import claim_folder
    from . import impacts
    from . import sweep as load

    model = open_model(args)
    overrides = circuit_overrides(model, args)
    models = voltage_models(model, args, (0, *load.CIRCUIT_MODELS))
    given = [load_value(model, value, "--load") for value in args.load or ()]
    stop_time, step = times(args, impacts.IMPACT_STEP)
    nominal = float(model.parameters["R_load"].start)
    checked = given or [nominal]
    unzipdir, instance = preflight(model, [{**overrides, "voltage_model": m, "R_load": r}
                                            for m in models for r in checked], "impact voltage")
    try:
        if given:
            loads = {load.ohm_text(r): r for r in given}
        else:
            estimate = load.circuit_constants(instance, overrides)["R_opt_estimate_ohm"]
            loads = {"paper's": nominal, "1/(omega_c C_p)": estimate}
        out = claim_folder(args.out, impacts.FILES, args.force, "run of impact-voltage")
        result = impacts.run_impacts(model, out, instance, loads, models, step, overrides, stop_time)
    except FmuRunError as error:
        raise UsageError(f"impact voltage (--stop-time {stop_time:g} s bounds the search for the first impact): "
                         f"{error}") from None
    finally:
        load.cleanup(instance, unzipdir)
    print("\n".join(impacts.impact_lines(result)))
    return 0
