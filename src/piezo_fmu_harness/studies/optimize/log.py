"""The log of ``piezo-fmu optimize`` (:mod:`piezo_fmu_harness.studies.optimize.search`):
``evaluations.jsonl``, one evaluation a line, and the check of each when ``--resume`` reads it
back (:func:`piezo_fmu_harness.store.open_folder`).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

from ...store import Damaged, numbers, require, vector

EVALUATIONS_FILE = "evaluations.jsonl"
#: The parts of an optimisation, in order, each evaluation's ``phase``.
PHASES = ("reference", "search", "grid", "sensitivity")


def record_check(problem):
    """The check of the recorded evaluations of ``problem``
    (:class:`piezo_fmu_harness.studies.optimize.search.Problem`), called on each in the order of the
    log, which numbers them in increasing order: a design of this problem's parameters, its phase,
    status, score and, when the FMU took it, the measures its terms are computed from (scored again
    on ``--resume``)."""
    needed = (problem.damping, "V_rms") if problem.objective == "perfectibility" else \
        ("amplitude", "transmissibility", "power")
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
