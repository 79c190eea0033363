"""The log of ``piezo-fmu optimize`` (:mod:`piezo_fmu_harness.studies.optimize.search`): its header
``optimize.json``, ``evaluations.jsonl``, one evaluation a line, and the check of each when
``--resume`` reads it back (:func:`piezo_fmu_harness.store.open_folder`).

This module never imports the simulation core.
"""

from __future__ import annotations

import json
from pathlib import Path

from ...store import Damaged, PointStore, numbers, open_folder, require, vector

HEADER_FILE = "optimize.json"
EVALUATIONS_FILE = "evaluations.jsonl"
#: The parts of an optimisation, in order, each evaluation's ``phase``.
PHASES = ("reference", "search", "grid", "sensitivity")


def record_check(problem):
    """The check of the recorded evaluations of ``problem``
    (:class:`piezo_fmu_harness.studies.optimize.search.Problem`), called on each in the order of the
    log, which numbers them in increasing order: a design of this problem's parameters, its phase,
    status, score and, when the FMU took it, the measures its terms are computed from (scored again
    on ``--resume``)."""
    needed = {"perfectibility": (problem.damping, "V_rms"), "forced": ("amplitude", "transmissibility", "power"),
              "random": ("ratio", "rms_with", "rms_without", "power")}[problem.objective]
    last = [-1]

    def check(record: dict) -> None:
        vector(record, "x", len(problem.names))
        require(record, {"phase": str, "status": str, "measures": dict, "seconds": float,
                         "objective": (float, type(None)), "terms": (dict, type(None))})
        if record["phase"] not in PHASES:
            raise Damaged(f"phase {record['phase']!r} is none of {', '.join(PHASES)}")
        numbers(record["measures"], record["measures"], "measure ")
        if record["status"] == "ok":
            require(record["measures"], dict.fromkeys(needed, float), "measure ")
        if record["index"] <= last[0]:
            raise Damaged(f"evaluation {record['index']} follows evaluation {last[0]}, but the log numbers them in "
                          "increasing order: a record of another run")
        last[0] = record["index"]
    return check


def open_optimization(model, problem, references: dict, folder: Path, resume: bool, force: bool,
                      settings: dict) -> tuple[Path, dict]:
    """Check the folder, then commit it to this optimisation (its header written, old evaluations
    dropped unless resuming); return ``(folder, cache of the evaluations recorded)``."""
    header = {"problem": problem.to_dict(), "references_given": references, "search": settings,
              "fmu": str(model.path), "fmu_guid": model.guid}
    folder, done, start_over = open_folder(folder, HEADER_FILE, header, ("problem", "references_given", "search"),
                                           resume, force, "--out", "optimisation", EVALUATIONS_FILE,
                                           record_check(problem))
    if start_over:
        PointStore(folder, EVALUATIONS_FILE).clear()
    (folder / HEADER_FILE).write_text(json.dumps(header, indent=2) + "\n")
    cache = {}
    for record in done.values():
        key = ("reference" if record.get("phase") == "reference" else "design",) + tuple(repr(v) for v in record["x"])
        cache[key] = record
    return folder, cache
