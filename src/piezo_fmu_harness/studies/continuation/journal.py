"""A continuation's folder, kept as it goes: what was asked goes to ``continuation.json`` (the
problem, the settings of the steps and of the seeds' shooting, the seeds' values, the most branches,
the FMU's GUID), and each finished task to ``points.jsonl``: a sweep of the seeds (``index`` 0 up, 1
down, with its ``records``) and a branch (``index`` 1 + the number its task was given, with the
``branch``), in the order they finished.

``--resume`` replays them: which seed a branch is followed from depends only on the branches
finished before it (:class:`piezo_fmu_harness.studies.continuation.study.Continuation`), so feeding
the recorded ones back in their order gives the same state, and only the tasks that were running
when the run stopped (and those that follow them) run again.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from ...store import Damaged, open_folder, require, within

HEADER_FILE = "continuation.json"


def header(study) -> dict:
    """What a continuation is asked to do (JSON-safe)."""
    return {"problem": asdict(study.problem), "settings": asdict(study.settings), "steady": asdict(study.steady),
            "lams": list(study.lams), "max_branches": study.max_branches}


def open_continuation(model, study, folder: Path, resume: bool, force: bool):
    """Check the folder and read its records (:func:`piezo_fmu_harness.store.open_folder`); change
    nothing. Returns ``(folder, records by index, start_over)``."""
    asked = {**header(study), "fmu_guid": model.guid}
    return open_folder(folder, HEADER_FILE, asked, tuple(k for k in asked if k != "fmu_guid"), resume, force,
                       "--out", "continuation", check=record_check(study.max_branches))


def record_check(max_branches: int):
    """The check of a record: a sweep of the seeds, or a branch of one of the tasks the study can
    have given out (one a branch, ``max_branches`` at most)."""
    def check(record: dict) -> None:
        if record["index"] < 2:
            require(record, {"direction": str, "records": list})
            if record["direction"] != ("up", "down")[record["index"]]:
                raise Damaged(f"record {record['index']} is the sweep {record['direction']!r}, not "
                              f"{('up', 'down')[record['index']]!r}")
            return
        within(record["index"], 2 + max_branches, "record")  # a branch a task, max_branches at most
        require(record, {"branch": dict})
        require(record["branch"], {"points": list, "events": list, "seeds": list, "ends": list, "evaluations": int},
                "the branch's ")
    return check
