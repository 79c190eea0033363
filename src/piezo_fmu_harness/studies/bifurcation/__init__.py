"""The bifurcation diagram (issues 23, 27): the section samples of ``p`` and the impacts per cycle
against frequency, swept up and down on the batch engine, every motion that does not settle
classified, a sample checked through the FMU (``piezo-fmu bifurcation``).

- :mod:`.study`: the sweeps on the engine, the FMU's checks, the Dataset, the summary and the files;
- :mod:`.figure`: the diagram.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu bifurcation``."""
    from ...options import band_options, batch_options, engine_once, model_options, results_folder
    from . import study

    diagram = commands.add_parser(
        "bifurcation", help="Poincare samples and impacts per cycle against frequency, up and down, motions classified",
        description="Sweep the damper's base frequency up and down on the batch engine (each frequency from where "
                    "the previous one's motion goes); at each, the section samples of p and the impacts per cycle "
                    "of the motion the trajectory reaches; a motion that reaches no orbit within the budget "
                    f"--max-cycles is chaotic or quasi-periodic only when a cloud of {study.CLOUD} companions shows "
                    "that it persists (and its Lyapunov exponent says so), else undecided. The FMU checks one point of "
                    "every kind of motion and --confirm more. Writes bifurcation.nc/.csv, points.json, "
                    "summary.json and bifurcation.png.")
    band_options(diagram, study.DEFAULTS, newton=False)
    batch_options(diagram, study.DEFAULT_CONFIRM, "along both sweeps")
    model_options(diagram)
    results_folder(diagram, "bifurcation")
    engine_once(diagram)
    diagram.add_argument("--no-progress", action="store_true", help="no progress bar")
    diagram.set_defaults(run=command)


def command(args) -> int:
    from ...fmu import discard
    from pathlib import Path

    from ...checks import PROG, device, engine_damper, make_backend, open_model, preflight, whole, worker_count
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from ...spec import UsageError
    from . import study

    model = open_model(args)
    jobs = worker_count(args)
    count = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                  "the FMU's checks cannot be negative")
    seed = whole(0 if args.seed is None else args.seed, "--seed", 0, "the seed is a whole number >= 0")
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
        args.newton_iterations = None
        spec = frequency_spec(args, model, instance, study.DEFAULTS)
        engine_damper(spec.values, batch, spec.ratios, spec.settings.samples)
        folder = Path(args.out)
        if (folder / "bifurcation.nc").exists() and not args.force:
            raise UsageError(f"--out {folder}: holds a bifurcation diagram already; give --force to replace it")
        folder.mkdir(parents=True, exist_ok=True)
        # every worker: the two chains take two, the clouds and the FMU's checks are tasks of their own
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, jobs))
        try:
            sweeps, wall = study.run(spec, backend, args.device, False if args.no_progress else None)
            checked = study.checks(spec, sweeps, backend, count, seed)
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    report = study.write(spec, sweeps, folder, wall, checked)
    work = report["start_periods"]
    print(f"{PROG} bifurcation: {report['points']} points in {wall:.1f} s ({work['sweeps'] + work['clouds']:,} "
          f"start-periods, {work['clouds']:,} of them in the clouds)")
    for direction, classes in report["classes"].items():
        print(f"  sweep {direction}: " + "; ".join(f"{kind} {c['count']}" for kind, c in classes.items()))
    checks = report["fmu_checks"]
    print(f"  the FMU, marched from {checks['checked']} of the points' starts: agrees on {checks['agree']}, parted "
          f"from the batch engine in a chaotic transient on {checks['parted']}, disagrees on {checks['disagree']}")
    print(f"  results in {folder}")
    return 0

