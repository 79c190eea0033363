"""The check of a study of many starts through the FMU: a sample of its starts, each marched through
the FMU (:func:`.destination.fmu_label`) as a task of the sweep engine, on every worker.

**The sample**, in proportion to the study (a check marches a start through the FMU, about 1,000
times slower than the batch engine marches one trajectory): one start of **every attractor** of the study,
across its band (an attractor keeps its name across the band), chaotic and quasi-periodic ones
included: the start that reached it soonest, and the next one (up to three) while the FMU has not
agreed on one of its starts; and ``--confirm`` starts more drawn at random with ``--seed``, one a
frequency (drawn at random too) until every frequency has one, then a second at each, and so on.
The undecided starts claim nothing (no attractor) and are not checked. What the checks cost beside
the marching, study by study, is in docs/harness.md (``checking_s`` and ``marching_s`` of each
``summary.json``).

A check **agrees** when the FMU's trajectory reaches the attractor the study gave the start; it
**parted** when the answers differ but the FMU's sections had left the study's (passed as
``track``) before the study's answer was known: a chaotic transient, whose end no double-precision
code predicts; otherwise it **disagrees**.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""

from __future__ import annotations

import numpy as np

from .destination import fmu_label


def candidates(starts: dict, key, tries: int) -> dict:
    """For each attractor (``key(record)``, its name across the band), up to ``tries`` of its starts,
    those labelled soonest first. The undecided starts are no attractor's: none is a candidate."""
    members: dict = {}
    for record in starts.values():
        if not undecided(record):
            members.setdefault(key(record), []).append(record)
    return {k: [r["index"] for r in sorted(rows, key=lambda r: (r["periods"], r["index"]))[:tries]]
            for k, rows in members.items()}


def undecided(record: dict) -> bool:
    return str(record.get("motion", "")).startswith("undecided")


def sample(starts: dict, count: int, seed: int, exclude=()) -> list[int]:
    """``count`` starts drawn at random (seeded) from those not in ``exclude`` and not undecided, one
    a frequency (``group``; the frequencies in a random order) until every frequency has one, then a
    second at each, and so on."""
    rng = np.random.default_rng(seed)
    left: dict = {}
    for index in sorted(set(starts) - set(exclude)):
        if not undecided(starts[index]):
            left.setdefault(starts[index]["group"], []).append(index)
    chosen: list[int] = []
    while left and len(chosen) < count:
        for group in rng.permutation(sorted(left)).tolist():
            if len(chosen) == count:
                break
            pool = left[group]
            chosen.append(pool.pop(int(rng.integers(len(pool)))))
            if not pool:
                del left[group]
    return sorted(chosen)


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


def confirm(backend, starts: dict, make, count: int, seed: int, key=None, tries: int = 3, what: str = "",
            progress=None) -> list[dict]:
    """The FMU's checks (:func:`confirm_task`) on ``backend`` of a sample of ``starts`` (records with
    ``index``, ``group``, ``periods`` and ``attractor``; see the module's text): every attractor
    (``key(record)``, by default its ``attractor``) from the start labelled soonest, and again from
    the next one (up to ``tries``) while the FMU has not agreed on one of its starts; and ``count``
    starts drawn at random with ``seed``. ``make(indices)`` makes the tasks' payloads. A progress bar
    (``what``) counts the checks on a terminal unless ``progress`` is False. Returns the checks'
    records by start index, each with its ``seconds``."""
    import sys

    from tqdm import tqdm

    key = key or (lambda record: record["attractor"])
    choice = candidates(starts, key, tries)
    first = {indices[0]: k for k, indices in choice.items()}
    todo = list(first) + sample(starts, count, seed, first)
    bar = tqdm(total=len(todo), unit="check", desc=f"{what}: FMU checks".lstrip(": "), dynamic_ncols=True,
               disable=(not progress) if progress is not None and todo else None if todo else True, file=sys.stderr)
    results: list[dict] = []
    try:
        for attempt in range(tries):
            tasks = [(p["index"], _timed_check, (p,)) for p in make(sorted(todo))] if todo else []
            if not tasks:
                break
            for _, record in backend.run_tasks(tasks):
                results.append(record)
                bar.update(1)
            agreed = {key(starts[r["index"]]) for r in results if r["agree"]}
            todo = [indices[attempt + 1] for k, indices in choice.items()
                    if k not in agreed and len(indices) > attempt + 1]
            bar.total += len(todo)
    finally:
        bar.close()
    return sorted(results, key=lambda r: r["index"])


def _timed_check(instance, payload: dict) -> dict:
    import time

    begin = time.perf_counter()
    return {**confirm_task(instance, payload), "seconds": time.perf_counter() - begin}


def tally(checks: list[dict], seconds: float) -> dict:
    """How the FMU's ``checks`` went, and the ``seconds`` they took: the head of a summary's
    ``fmu_checks``."""
    verdicts = [c["verdict"] for c in checks]
    return {"checked": len(checks), "agree": verdicts.count("agrees"), "parted": verdicts.count("parted"),
            "disagree": verdicts.count("disagrees"), "seconds": seconds}


def sentence(counts: dict, what: str = "start") -> str:
    """A :func:`tally` as a sentence: from how many of the study's ``what`` the FMU was marched, and
    what it found."""
    from ..wording import counted

    return (f"the FMU, marched from {counted(counts['checked'], what)} in {counts['seconds']:.1f} s: agrees on "
            f"{counts['agree']}, parted from the batch engine in a chaotic transient on {counts['parted']}, "
            f"disagrees on {counts['disagree']}")
