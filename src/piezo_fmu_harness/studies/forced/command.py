"""The forced response on the command line: ``piezo-fmu frequency-response``."""

from __future__ import annotations

import signal
import sys

from ...fmu import discard
from ...checks import PROG, interrupt, make_backend, open_model, preflight, worker_count
from ...spec import UsageError
from ...wording import counted


def frequency_response(args) -> int:
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from . import chains as fr
    from . import results as frequency_results

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
                print(f"{PROG} frequency-response: {remaining} of {counted(run.total, 'point')} to run on {backend.description}",
                      file=sys.stderr)
                try:
                    fr.execute(run, backend, progress=False if args.no_progress else None)
                except KeyboardInterrupt:
                    print(f"\n{PROG} frequency-response: interrupted; {len(run.done)} of {counted(run.total, 'point')} are saved "
                          f"in {run.folder / 'points.jsonl'}; run the same command with --resume to finish",
                          file=sys.stderr)
                    return 130
        finally:
            signal.signal(signal.SIGTERM, previous)
    finally:
        instance.free()
        discard(unzipdir)
    result = frequency_results.finish(model, run, jobs)
    print("\n".join(frequency_results.summary_lines(result["summary"])))
    print(f"  results in {run.folder}")
    return 0
