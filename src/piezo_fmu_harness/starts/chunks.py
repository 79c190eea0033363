"""The chunks of a study of many starts (basins, fractions) on the sweep engine, kept as they
finish.

A study of many starts splits them into chunks of a fixed size (so that ``--resume`` finds the same
chunks again); each chunk is a task of the engine (:mod:`piezo_fmu_harness.engine`), marched by the
study on the batch engine, and its record (its starts' labels and the attractors it met,
:mod:`.attractors`) is appended to ``points.jsonl`` as it arrives.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..store import Damaged, PointStore, require
from ..wording import counted

#: Chunks a study's starts are split into (the batch engine is the faster a start the more starts
#: it marches at once, and a few chunks a worker keep the workers busy to the end) ...
CHUNKS = 8
#: ... of at least this many starts.
CHUNK = 512


def chunk_size(count: int) -> int:
    """Starts in a chunk of a study of ``count`` starts (fixed by ``count`` alone: ``--resume``
    finds the same chunks again)."""
    return max(CHUNK, -(-count // CHUNKS))


def chunks(count: int) -> list[list[int]]:
    """The start indices of each chunk."""
    size = chunk_size(count)
    return [list(range(begin, min(begin + size, count))) for begin in range(0, count, size)]


def check_chunk(record: dict, starts: list[tuple[int, int]]) -> None:
    """Raise :class:`~piezo_fmu_harness.store.Damaged` unless ``record`` is the chunk of this
    study that holds ``starts`` (``(index, group)`` of each, in order; a group is a drive): its
    starts with their labels and periods, and the attractors they reached."""
    require(record, {"starts": list, "attractors": list})
    groups = {group for _, group in starts}
    for k, attractor in enumerate(record["attractors"]):
        where = f"attractor {k}'s "
        if not isinstance(attractor, dict):
            raise Damaged(f"attractor {k} is not an object")
        require(attractor, {"kind": str, "group": int}, where)
        if attractor["group"] not in groups:
            raise Damaged(f"{where}drive {attractor['group']} is not this chunk's: a record of another run")
        if attractor["kind"] == "orbit":
            require(attractor, {"order": int, "impacts": list, "sections": list}, where)
    for k, start in enumerate(record["starts"]):
        if not isinstance(start, dict):
            raise Damaged(f"start {k} of the chunk is not an object")
        require(start, {"index": int, "group": int, "label": int, "periods": int}, f"start {k}'s ")
        if not -2 <= start["label"] < len(record["attractors"]):
            raise Damaged(f"start {start['index']}'s label {start['label']} names no attractor of its chunk")
    if [(start["index"], start["group"]) for start in record["starts"]] != starts:
        raise Damaged(f"chunk {record['index']} holds other starts than this study's chunk {record['index']}: a "
                      "record of another run")


def backend_for(args, model, unzipdir: str, instance, jobs: int):
    """The engine's backend the options ask for; this process's instance for ``--jobs 1``."""
    from ..checks import make_backend
    from ..engine import InProcess

    if jobs == 1 and not (args.scheduler or args.dask_local):
        return InProcess(instance)
    return make_backend(args, model, unzipdir, jobs)


def execute(what: str, tasks: list, folder: Path, done: dict, start_over: bool, header_file: str, header: dict,
            backend, total: int, progress, device: str) -> bool:
    """Run the chunk ``tasks`` not in ``done`` (by chunk index) on ``backend``, appending each
    record as it arrives; ``total`` starts in all, for the progress bar. False when interrupted
    (Ctrl-C), after saying how to resume."""
    from tqdm import tqdm

    from ..checks import PROG

    print(f"{PROG} {what}: {counted(total, 'start')} on the batch engine ({device}), in chunks on {backend.description}",
          file=sys.stderr)
    if start_over:
        PointStore(folder).clear()
    (folder / header_file).write_text(json.dumps(header, indent=2) + "\n")
    finished = sum(len(record["starts"]) for record in done.values())
    bar = tqdm(total=total, initial=finished, unit="start", desc=what, dynamic_ncols=True,
               disable=(not progress) if progress is not None else None, file=sys.stderr)
    try:
        with PointStore(folder) as store:
            for _, record in backend.run_tasks([task for task in tasks if task[0] not in done]):
                store.append(record)
                done[record["index"]] = record
                bar.update(len(record["starts"]))
    except KeyboardInterrupt:
        bar.close()
        print(f"\n{PROG} {what}: interrupted; {counted(sum(len(r['starts']) for r in done.values()), 'start')} "
              "saved; run "
              "the same command with --resume", file=sys.stderr)
        return False
    bar.close()
    return True
