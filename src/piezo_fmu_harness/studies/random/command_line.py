"""``piezo-fmu random``: the options checked and turned into a :class:`~.spec.RandomSpec`, the chunks
marched, the FMU's checks, the files. Every bad option is refused before any work, naming the
option, the value and what is allowed."""

from __future__ import annotations

import math
import sys
import time

from ...random_response.spec import RandomSpec


def spec_of(args, model, instance) -> RandomSpec:
    """The study the options ask for, every option checked (the excitation's options by
    :mod:`piezo_fmu_harness.random_response.arguments`)."""
    from ...checks import assignments, whole
    from ...random_response.arguments import damper_values, excitation_spec
    from ...spec import UsageError
    from . import study

    values = damper_values(args, model, instance, assignments(model, args.set))
    spec = excitation_spec(args, values, "random")
    envelope = _envelope(args.envelope)
    confirm = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                    "the FMU's checks cannot be negative")
    save = args.save_input
    if save is not None and not 0 <= save < spec.realizations:
        raise UsageError(f"--save-input {save}: no such realization; allowed range [0, {spec.realizations - 1}]")
    return spec.with_(envelope=envelope, device=args.device, confirm=min(confirm, spec.realizations), save_input=save)


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
        engine_damper(spec.values, batch)
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
