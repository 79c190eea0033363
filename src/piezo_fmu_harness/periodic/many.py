"""Studies of many starts (basins, fractions): their chunks on the sweep engine, kept as they
finish, and the check of their answers through the FMU.

A study of many starts splits them into chunks of a fixed size (so that ``--resume`` finds the same
chunks again); each chunk is a task of the engine (:mod:`piezo_fmu_harness.engine`), marched by the
study on the batch engine, and its record (its starts' labels and the attractors it met,
:mod:`.attractors`) is appended to ``points.jsonl`` as it arrives.

The FMU then checks the answer: for each attractor, the start that reached it soonest, and a seeded
random sample of the other starts, are marched through the FMU (:func:`.confirm.fmu_label`), each
a task too. A check **agrees** when the FMU's trajectory reaches the attractor the study gave the
start (for an undecided point of the bifurcation diagram, when it too reaches no orbit within the
study's budget; the undecided starts of the basins and the fractions claim nothing and are not
checked); it **parted** when the answers differ but the FMU's sections had left the study's (passed as
``track``) before the study's answer was known: a chaotic transient, whose end no double-precision
code predicts; otherwise it **disagrees**.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..store import Damaged, PointStore, require
from .confirm import fmu_label

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

    print(f"{PROG} {what}: {total} starts on the batch engine ({device}), in chunks on {backend.description}",
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
        print(f"\n{PROG} {what}: interrupted; {sum(len(r['starts']) for r in done.values())} starts are saved; run "
              "the same command with --resume", file=sys.stderr)
        return False
    bar.close()
    return True


def candidates(starts: dict, tries: int) -> dict[int, list[int]]:
    """For each attractor, up to ``tries`` of its starts, those labelled soonest first. The undecided
    starts are no attractor's and claim nothing (issue 31): none is checked."""
    members: dict[int, list[dict]] = {}
    for record in starts.values():
        if not undecided(record):
            members.setdefault(record["attractor"], []).append(record)
    return {k: [r["index"] for r in sorted(rows, key=lambda r: (r["periods"], r["index"]))[:tries]]
            for k, rows in members.items()}


def undecided(record: dict) -> bool:
    return str(record.get("motion", "")).startswith("undecided")


def sample(starts: dict, count: int, seed: int, exclude=()) -> list[int]:
    """``count`` starts drawn at random (seeded) from those not in ``exclude`` and not undecided."""
    others = sorted(set(starts) - set(exclude) - {i for i, r in starts.items() if undecided(r)})
    rng = np.random.default_rng(seed)
    return sorted(int(i) for i in rng.choice(others, size=min(count, len(others)), replace=False)) if others else []


def confirm_task(instance, payload: dict) -> dict:
    """A task: the FMU's label for one start (``payload``: the drive, the start, the periods the
    study marched it, the drive's attractors, the study's label)."""
    result = fmu_label(instance, payload["values"], payload["omega"], payload["amplitude"], payload["samples"],
                       payload["start"], payload["periods"], payload["attractors"], payload.get("track"),
                       payload.get("cap", 0), prefer=payload["study"])
    agree = result["attractor"] == payload["study"]
    kind = next((a["kind"] for a in payload["attractors"] if a["id"] == payload["study"]), None)
    if kind == "undecided" and not agree:
        # undecided is no attractor: the FMU agrees when it too reaches no orbit within the budget
        agree = result["periods"] > payload["periods"]
    parted = result["diverged_at"] is not None and result["diverged_at"] <= payload["periods"]
    return {"index": payload["index"], "study": payload["study"], "fmu": result["attractor"],
            "fmu_motion": result["motion"], "fmu_periods": result["periods"], "study_periods": payload["periods"],
            "study_motion": next((a.get("motion") for a in payload["attractors"] if a["id"] == payload["study"]), None),
            "diverged_at": result["diverged_at"],
            "verdict": "agrees" if agree else "parted" if parted else "disagrees", "agree": agree}


def confirm(backend, groups: list[tuple], tries: int = 3) -> list[dict]:
    """The FMU's checks (:func:`confirm_task`) on ``backend``, for each group ``(payloads, starts,
    count, seed)`` of starts (a drive's): every attractor from the start labelled soonest, and again
    from the next one (up to ``tries``) while the FMU has not agreed on one of its starts; and
    ``count`` starts drawn at random. ``payloads(indices)`` makes the tasks' payloads. All the
    groups' checks of a round run together. Returns the checks' records by start index."""
    options = [candidates(starts, tries) for _, starts, _, _ in groups]
    todo = []
    for (_, starts, count, seed), choice in zip(groups, options):
        first = [indices[0] for indices in choice.values()]
        todo.append(first + sample(starts, count, seed, first))
    results: list[dict] = []
    for attempt in range(tries):
        tasks = [(p["index"], confirm_task, (p,)) for (make, _, _, _), chosen in zip(groups, todo) if chosen
                 for p in make(chosen)]
        if not tasks:
            break
        results += [record for _, record in backend.run_tasks(tasks)]
        agreed = {r["study"] for r in results if r["agree"]}
        todo = [[indices[attempt + 1] for k, indices in choice.items() if k not in agreed and len(indices) > attempt + 1]
                for choice in options]
    return sorted(results, key=lambda r: r["index"])
