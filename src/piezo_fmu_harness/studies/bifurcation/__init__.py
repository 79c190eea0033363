"""The bifurcation diagram: the section samples of ``p`` and the impacts per cycle
against frequency, swept up and down on the batch engine, every motion that does not settle
classified, a sample checked through the FMU (``piezo-fmu bifurcation``).

- :mod:`.study`: the sweeps on the engine, the FMU's checks, the Dataset, the summary and the files;
- :mod:`.figure`: the diagram.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu bifurcation``."""
    from ...options import (drive_options, frequency_options, many_start_options, model_options, results_options,
                            work_options)
    from . import study

    diagram = commands.add_parser(
        "bifurcation", help="Poincare samples against frequency, up and down",
        description="Sweep the damper's base frequency up and down on the batch engine (each frequency from where "
                    "the previous one's motion goes); at each, the section samples of p and the impacts per cycle "
                    "of the motion the trajectory reaches; a motion that reaches no orbit within the budget "
                    f"--max-cycles is chaotic or quasi-periodic only when a cloud of {study.CLOUD} companions shows "
                    "that it persists (and its Lyapunov exponent says so), else undecided. The FMU checks one point of "
                    f"every kind of motion and --confirm random points more. Writes {', '.join(study.FILES)}; what "
                    "was asked goes to bifurcation.json and each frequency and cloud to points.jsonl (--resume).")
    drive_options(diagram)
    frequency_options(diagram, study.DEFAULTS)
    many_start_options(diagram, study.DEFAULTS, study.DEFAULT_CONFIRM)
    model_options(diagram)
    results_options(diagram, "bifurcation", resumable=True)
    work_options(diagram)
    diagram.set_defaults(run=command)


def command(args) -> int:
    import time

    from ...fmu import discard
    from ...checks import PROG, device, engine_damper, make_backend, open_model, preflight, whole, worker_count
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from ...starts.fmu_checks import sentence
    from ...wording import counted
    from . import chains, study

    model = open_model(args)
    jobs = worker_count(args)
    count = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                  "the FMU's checks cannot be negative")
    seed = whole(args.seed, "--seed", 0, "the seed is a whole number >= 0")
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
        spec = frequency_spec(args, model, instance, study.DEFAULTS)
        engine_damper(spec.values, batch, spec.ratios, spec.settings.samples)
        header = {**chains.plain(spec, args.device), "fmu_guid": model.guid}
        folder, done, start_over = chains.open_diagram(model, header, args.out, args.resume, args.force)
        # every worker: the two chains take two, the clouds and the FMU's checks are tasks of their own
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, jobs))
        progress = False if args.no_progress else None
        begin = time.perf_counter()
        try:
            sweeps = chains.run(header, backend, folder, done, start_over, progress)
            if sweeps is None:
                return 130
            marched = time.perf_counter()
            checked = chains.checks(spec, sweeps, backend, count, seed, progress)
            times = {"marching_s": marched - begin, "checking_s": time.perf_counter() - marched}
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    report = study.write(spec, sweeps, folder, times, checked, begin)
    work = report["start_periods"]
    print(f"{PROG} bifurcation: {counted(report['points'], 'point')} in {report['wall_s']:.1f} s "
          f"({report['marching_s']:.1f} s marching, {report['checking_s']:.1f} s checking; "
          f"{counted(work['sweeps'] + work['clouds'], 'start-period')}, {work['clouds']:,} of them in the clouds)")
    for direction, classes in report["classes"].items():
        print(f"  sweep {direction}: " + "; ".join(f"{kind} {c['count']}" for kind, c in classes.items()))
    print(f"  {sentence(report['fmu_checks'], 'point')}")
    print(f"  results in {folder}")
    return 0
