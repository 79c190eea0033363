"""``piezo-fmu random``: the options checked and turned into a :class:`~.spec.RandomSpec`, the chunks
marched, the FMU's checks, the files. Every bad option is refused before any work, naming the
option, the value and what is allowed."""

from __future__ import annotations

import math
import sys
import time

from . import DEFAULT_BAND, DEFAULT_LEVEL, PSD_KINDS, STEPS_PER_TOP
from ...random_response.spec import RandomSpec, default_warmup

#: The FMU's start state of every realization: at rest (the base too, ``y = 0``).
START = {"p0": 0.0, "q0": 0.0, "dp0": 0.0, "dq0": 0.0}


def _source(args) -> tuple[dict, tuple]:
    """The excitation's kind and parameters, and its levels."""
    from ...excitation import CLOUGH_PENZIEN_SOILS, KANAI_TAJIMI_SOILS, Record, TablePSD
    from ...spec import UsageError

    if args.record is not None:
        if args.level is not None or args.levels is not None:
            raise UsageError(f"--record {args.record}: a record has no level; allowed: --level or --levels with --psd")
        try:
            record = Record.from_csv(args.record)
        except (OSError, ValueError) as error:
            raise UsageError(f"--record {args.record}: {error}") from None
        return {"kind": "record", "step": record.step, "acceleration": record.acceleration.tolist(),
                "name": str(args.record)}, ()
    if args.levels is not None:
        try:
            levels = tuple(float(text) for text in args.levels.split(","))
        except ValueError:
            raise UsageError(f"--levels {args.levels}: give levels as G1,G2,... ((m/s^2)^2/Hz, each > 0)") from None
    else:
        levels = (DEFAULT_LEVEL if args.level is None else args.level,)
    bad = [g for g in levels if not (math.isfinite(g) and g > 0.0)]
    if bad:
        raise UsageError(f"--level(s) {bad[0]!r}: a one-sided PSD level must be a finite number > 0; allowed range "
                         "(0, inf) (m/s^2)^2/Hz")
    kind = args.psd
    band = args.band
    if kind == "white":
        fmin, fmax = DEFAULT_BAND if band is None else band
        return {"kind": "white", "fmin": fmin, "fmax": fmax}, levels
    if band is not None and band[0] != 0.0:
        raise UsageError(f"--band {band[0]:g} {band[1]:g}: the ground filters and a table start where they start; "
                         "allowed: --band 0 FMAX (FMAX the cut, Hz); the low-frequency treatment is --f-low")
    upper = 25.0 if band is None else band[1]
    if kind in ("kanai-tajimi", "clough-penzien"):
        preset = (KANAI_TAJIMI_SOILS if kind == "kanai-tajimi" else CLOUGH_PENZIEN_SOILS)[args.soil]
        source = {"kind": kind, "omega_g": args.omega_g or preset[0], "zeta_g": args.zeta_g or preset[1],
                  "upper": upper}
        if kind == "clough-penzien":
            source.update(omega_f=args.omega_f or preset[2], zeta_f=args.zeta_f or preset[3])
        return source, levels
    try:
        table = TablePSD.from_csv(kind, upper=math.nan if band is None else upper)
    except (OSError, ValueError) as error:
        raise UsageError(f"--psd {kind}: {error}; allowed: one of {', '.join(PSD_KINDS)}, or a CSV table") from None
    if args.level is None and args.levels is None:
        levels = (table.level,)
    return {"kind": "table", "frequencies": table.frequencies.tolist(), "densities": table.densities.tolist(),
            "upper": table.upper, "name": str(kind)}, levels


def _values(args, model, instance) -> dict:
    from ...checks import assignments, load_value
    from ...circuit import circuit_constants
    from ...spec import UsageError

    given = assignments(model, args.set)
    values = {**model.defaults(), **given}
    starts = {name: given[name] for name in START if given.get(name, 0.0) != 0.0}
    if starts:
        raise UsageError(f"--set {', '.join(f'{k}={v!r}' for k, v in starts.items())}: every realization starts from rest, "
                         "with the base; allowed: 0 (or leave it out)")
    values.update(START)
    values["voltage_model"] = 2 if args.voltage_model is None else args.voltage_model
    if values["voltage_model"] not in (0, 2):
        raise UsageError(f"--voltage-model {values['voltage_model']}: the batch engine carries a patch's voltage only "
                         "where it acts back on the barrier; allowed: 0 (quasi-static, nothing harvested) or 2 (the "
                         "coupled circuit)")
    if args.load is not None:
        values["R_load"] = load_value(model, args.load, "--load")
    elif "R_load" not in {text.split("=")[0].strip() for text in args.set}:
        values["R_load"] = circuit_constants(instance, values)["R_opt_estimate_ohm"]
    if not values["C"] > 0.0:
        raise UsageError(f"--set C={values['C']!r}: without damping the main mass's response to a stationary input never "
                         "settles (its variance grows without end); allowed range (0, inf) N.s/m")
    return values


def spec_of(args, model, instance) -> RandomSpec:
    """The study the options ask for, every option checked."""
    from ...checks import positive, whole
    from ...spec import UsageError
    from . import study

    source, levels = _source(args)
    values = _values(args, model, instance)
    record = source["kind"] == "record"
    if record:
        step = source["step"]
        if args.step is not None and abs(args.step - step) > 1e-6 * step:
            raise UsageError(f"--step {args.step!r}: a record is marched at its own step, {step!r} s; allowed: "
                             "that step (resample the record to another)")
        realizations = whole(1 if args.realizations is None else args.realizations, "--realizations", 1, "")
        if realizations != 1:
            raise UsageError(f"--realizations {realizations}: a record is one realization; allowed: 1")
    else:
        top = source["fmax"] if source["kind"] == "white" else source["upper"]
        step = positive(1.0 / (STEPS_PER_TOP * top) if args.step is None else args.step, "--step",
                        "the input's step", "s")
        realizations = whole(study.DEFAULT_REALIZATIONS if args.realizations is None else args.realizations,
                             "--realizations", 1, "at least one realization")
    try:
        from ...random_response.spec import build_source
        from ...excitation import Excitation
        excitation = Excitation(build_source(source, levels[0] if levels else None), step=step, f_low=args.f_low)
    except ValueError as error:
        raise UsageError(f"--psd/--band/--step/--f-low: {error}") from None
    f_low = excitation.f_low
    if args.warmup is not None:
        warmup = args.warmup
        if not (math.isfinite(warmup) and warmup >= 0.0):
            raise UsageError(f"--warmup {warmup!r}: allowed range [0, inf) s")
    else:
        warmup = 0.0 if record else default_warmup(values, f_low)
    if args.duration is not None:
        duration = positive(args.duration, "--duration", "the window analysed", "s")
    elif record:
        duration = len(source["acceleration"]) * step - warmup
        if duration <= 0.0:
            raise UsageError(f"--warmup {warmup:g}: the record lasts {len(source['acceleration']) * step:g} s; allowed: "
                             "a warm-up shorter than the record")
    else:
        duration = study.DEFAULT_DURATION
    if duration < 2.0 * step:
        raise UsageError(f"--duration {duration:g}: the window must hold two steps of {step:g} s at least")
    envelope = _envelope(args.envelope)
    seed = whole(0 if args.seed is None else args.seed, "--seed", 0, "the seed is a whole number >= 0")
    confirm = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                    "the FMU's checks cannot be negative")
    if confirm > realizations:
        confirm = realizations
    save = args.save_input
    if save is not None and not 0 <= save < realizations:
        raise UsageError(f"--save-input {save}: no such realization; allowed range [0, {realizations - 1}]")
    return RandomSpec(source, levels, values, realizations, float(duration), float(warmup), float(step), float(f_low),
                      envelope, seed, args.device, confirm, save)


def _envelope(text) -> dict | None:
    from ...excitation import JenningsHousnerTsai, ShinozukaSato
    from ...spec import UsageError

    if text is None:
        return None
    kind, _, numbers = text.partition(":")
    forms = {"jennings": ("jennings-housner-tsai", JenningsHousnerTsai, ("t1", "t2", "c")),
             "shinozuka": ("shinozuka-sato", ShinozukaSato, ("b1", "b2"))}
    if kind not in forms:
        raise UsageError(f"--envelope {text}: allowed: jennings:T1,T2,C or shinozuka:B1,B2")
    name, cls, fields = forms[kind]
    try:
        values = [float(x) for x in numbers.split(",")]
        if len(values) != len(fields):
            raise ValueError(f"{len(fields)} numbers are needed ({', '.join(fields)})")
        cls(*values)
    except ValueError as error:
        raise UsageError(f"--envelope {text}: {error}") from None
    return {"kind": name, "parameters": dict(zip(fields, values))}


def run(args) -> int:
    from ...checks import device, engine_damper, open_model, preflight, worker_count
    from ...fmu import discard
    from ...starts.chunks import backend_for
    from . import study

    model = open_model(args)
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
        spec = spec_of(args, model, instance)
        engine_damper(spec.values, getattr(batch, "damper_error", None))
        folder, done, start_over = study.open_random(model, spec, args.out, args.resume, args.force)
        backend = backend_for(args, model, unzipdir, instance, jobs)
        begin = time.perf_counter()
        try:
            if not _march(spec, folder, done, start_over, model, backend, args.no_progress):
                return 130
            marched = time.perf_counter() - begin
            checks = _check(spec, backend, args.no_progress)
            checked = time.perf_counter() - begin - marched
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    report = study.write(spec, done, checks, folder, {"marching_s": marched, "checking_s": checked})
    _say(spec, report, folder)
    return 0


def _march(spec: RandomSpec, folder, done: dict, start_over: bool, model, backend, quiet: bool) -> bool:
    """The chunks not in ``done`` on ``backend``, each record appended as it arrives; False when
    interrupted (Ctrl-C), after saying how to resume."""
    import json

    from tqdm import tqdm

    from ...checks import PROG
    from ...store import PointStore
    from . import study

    from ...wording import counted

    print(f"{PROG} random: {counted(spec.realizations, 'realization')} x {counted(max(len(spec.levels), 1), 'level')}, "
          f"with and without the damper, {spec.warmup:.3g} s of warm-up + {spec.duration:.3g} s, on the batch engine "
          f"({spec.device}), in chunks on {backend.description}", file=sys.stderr)
    if start_over:
        PointStore(folder).clear()
    (folder / study.HEADER_FILE).write_text(json.dumps({**spec.to_dict(), "fmu_guid": model.guid}, indent=2) + "\n")
    finished = sum(len(record["realizations"]) for record in done.values())
    bar = tqdm(total=spec.realizations, initial=finished, unit="realization", desc="random", dynamic_ncols=True,
               disable=True if quiet else None, file=sys.stderr)
    try:
        with PointStore(folder) as store:
            for _, record in backend.run_tasks([task for task in study.tasks(spec) if task[0] not in done]):
                store.append(record)
                done[record["index"]] = record
                bar.update(len(record["realizations"]))
    except KeyboardInterrupt:
        bar.close()
        print(f"\n{PROG} random: interrupted; the finished realizations are saved; run the same command with --resume",
              file=sys.stderr)
        return False
    bar.close()
    return True


def _check(spec: RandomSpec, backend, quiet: bool) -> list[dict]:
    """The FMU's checks (:func:`.study.check_tasks`) on ``backend``, a progress bar counting them."""
    from tqdm import tqdm

    from . import study

    tasks = study.check_tasks(spec)
    bar = tqdm(total=len(tasks), unit="check", desc="random: FMU checks", dynamic_ncols=True,
               disable=True if quiet or not tasks else None, file=sys.stderr)
    checks = []
    try:
        for _, record in backend.run_tasks(tasks):
            checks.append(record)
            bar.update(1)
    finally:
        bar.close()
    return checks


def _interval(bounds) -> str:
    """A 95% interval as said, or why there is none (one realization cannot give one)."""
    low, high = bounds
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return " (no interval from one realization)"
    return f" (95%: {low:.3f}-{high:.3f})"


def _say(spec: RandomSpec, report: dict, folder) -> None:
    from ...checks import PROG

    for entry in report["levels"]:
        level = "the record" if entry["level"] is None else f"level {entry['level']:.3g} (m/s^2)^2/Hz"
        acc = entry.get("base_acceleration_rms")
        print(f"{PROG} random: {level}" + (f", RMS base acceleration {acc:.3g} m/s^2" if acc else "") +
              f": RMS relative displacement {entry['with']['rms_relative'] * 1e3:.3g} mm with the damper, "
              f"{entry['without']['rms_relative'] * 1e3:.3g} mm without: ratio {entry['ratio']:.3f}"
              f"{_interval(entry['ratio_ci'])}; {entry['with']['impacts_per_second']:.3g} "
              f"impacts/s, {entry['with']['power'] * 1e3:.3g} mW harvested")
    from ...wording import counted

    agree = sum(1 for check in report["fmu_checks"]["checks"] if check["agrees"])
    print(f"  the FMU, marched alone on {counted(len(report['fmu_checks']['checks']), 'realization')}: agrees on "
          f"{agree} (its motion within 1e-9 m over the first second" +
          (")" if spec.realizations < 2 else ", its RMS and impacts within the realizations' scatter)"))
    print(f"  results in {folder}")
