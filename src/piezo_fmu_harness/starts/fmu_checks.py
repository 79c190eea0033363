"""The check of a study of many starts through the FMU: for each attractor, the start that reached it
soonest, and a seeded random sample of the other starts, are marched through the FMU
(:func:`.destination.fmu_label`), each a task of the sweep engine.

A check **agrees** when the FMU's trajectory reaches the attractor the study gave the start (for an
undecided point of the bifurcation diagram, when it too reaches no orbit within the study's budget;
the undecided starts of the basins and the fractions claim nothing and are not checked); it
**parted** when the answers differ but the FMU's sections had left the study's (passed as
``track``) before the study's answer was known: a chaotic transient, whose end no double-precision
code predicts; otherwise it **disagrees**.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""

from __future__ import annotations

import numpy as np

from .destination import fmu_label


def candidates(starts: dict, tries: int) -> dict[int, list[int]]:
    """For each attractor, up to ``tries`` of its starts, those labelled soonest first. The undecided
    starts are no attractor's and claim nothing: none is checked."""
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
