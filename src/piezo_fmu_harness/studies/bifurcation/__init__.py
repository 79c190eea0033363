"""The bifurcation diagram (issue 23): the section samples of ``p`` and the impacts per cycle against
frequency, swept up and down, every motion that does not settle classified
(``piezo-fmu bifurcation``).

- :mod:`.study`: the sweeps on the engine, the Dataset, the summary and the files;
- :mod:`.figure`: the diagram.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu bifurcation``."""
    from ...options import band_options, engine_once, model_options, results_folder
    from . import study

    diagram = commands.add_parser(
        "bifurcation", help="Poincare samples and impacts per cycle against frequency, up and down, motions classified",
        description="Sweep the damper's base frequency up and down (each frequency from the previous state); at "
                    "each, after the transients, the section samples of p and the impacts per cycle; a motion that "
                    "is not periodic is classified (quasi-periodic, strongly modulated, chaotic, transient) by its "
                    "largest Lyapunov exponent. Writes bifurcation.nc/.csv, summary.json and bifurcation.png.")
    band_options(diagram, study.DEFAULTS)
    model_options(diagram)
    results_folder(diagram, "bifurcation")
    engine_once(diagram)
    diagram.set_defaults(run=command)


def command(args) -> int:
    import shutil
    from pathlib import Path

    from ...checks import PROG, make_backend, open_model, preflight, worker_count
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from ...spec import UsageError
    from . import study

    model = open_model(args)
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        spec = frequency_spec(args, model, instance, study.DEFAULTS)
        folder = Path(args.out)
        if (folder / "bifurcation.nc").exists() and not args.force:
            raise UsageError(f"--out {folder}: holds a bifurcation diagram already; give --force to replace it")
        folder.mkdir(parents=True, exist_ok=True)
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, min(jobs, 2)))
        try:
            sweeps, wall = study.run(spec, backend)
        finally:
            backend.close()
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    report = study.write(spec, sweeps, folder, wall)
    print(f"{PROG} bifurcation: {report['points']} points in {wall:.1f} s")
    for direction, classes in report["classes"].items():
        print(f"  sweep {direction}: " + "; ".join(f"{kind} {c['count']}" for kind, c in classes.items()))
    print(f"  results in {folder}")
    return 0
