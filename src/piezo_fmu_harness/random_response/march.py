"""A chunk of a random-excitation study's realizations, marched on the batch engine: each realization's
input generated (:mod:`piezo_fmu_harness.excitation`), streamed block by block, and marched with and
without the damper at every level, the accounts restarted at the window's start.

A realization's record holds, for each level and each damper, what the study reports of it: the
mean squares of the main mass's displacement relative to the base and absolute (m^2, over the
steps' ends in the window), their largest excursions (m), the contact onsets, the energy harvested
in both loads (J), and the energy ledger's balance (J: the base's work less the stored energy's
change, the dissipation and the harvested energy, over the window). The chunk's record adds the
Welch sums of the relative displacement of its realizations that feed the response PSD.

The inputs of every level are the first level's scaled by ``sqrt(level / first level)``: the
levels share their random numbers (a study's effectiveness curve compares one set of records at
several intensities).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .spec import BLOCK, PSD_REALIZATIONS, PSD_SEGMENT, RandomSpec
from .statistics import Welch

#: The two cases of every realization.
DAMPERS = ("with", "without")


def psd_length(spec: RandomSpec) -> int:
    """The Welch segment (samples): a power of two at least :data:`PSD_SEGMENT` s long, at most the window."""
    length = 1 << max(4, math.ceil(math.log2(PSD_SEGMENT / spec.step)))
    while length > spec.window_steps and length > 16:
        length //= 2
    return length


def march_chunk(instance, spec_dict: dict, number: int, realizations: list[int]) -> dict:
    """A task: the realizations ``realizations`` (chunk ``number``) of the study ``spec_dict``, on the
    batch engine (``instance``, the worker's FMU, is not used: the check marches it)."""
    from piezo_fmu.solver.batch import damper
    from piezo_fmu.solver.batch.input_ensemble import InputEnsemble

    begin = time.perf_counter()
    spec = RandomSpec.from_dict(spec_dict)
    n = len(realizations)
    levels = spec.levels or (None,)
    scales = [math.sqrt(level / levels[0]) if level is not None else 1.0 for level in levels]
    ensembles = {(k, case): InputEnsemble(damper(spec.values if case == "with" else spec.without), spec.step,
                                           np.zeros((n, 4)), device=spec.device)
                 for k in range(len(levels)) for case in DAMPERS}
    feed = [j for j, r in enumerate(realizations) if r < PSD_REALIZATIONS]
    welch = {key: Welch(spec.step, psd_length(spec), len(feed)) for key in ensembles} if feed else {}
    chunk = spec.excitation(0).chunk(realizations)
    stored = {}
    done = 0
    while done < spec.steps:
        count = min(BLOCK, spec.steps - done)
        if done < spec.warmup_steps:
            count = min(count, spec.warmup_steps - done)
        y, v = chunk.take(count)
        nodes, slopes = np.ascontiguousarray(y.T), np.ascontiguousarray(v.T)
        for (k, case), ensemble in ensembles.items():
            positions = ensemble.advance(nodes * scales[k], slopes * scales[k])
            if done >= spec.warmup_steps and feed:
                welch[k, case].add(positions[feed] - nodes[feed, 1:] * scales[k])
        done += count
        if done == spec.warmup_steps:
            for (k, case), ensemble in ensembles.items():
                ensemble.restart_accounts()
                stored[k, case] = ensemble.energy(nodes[:, -1] * scales[k])
    if not spec.warmup_steps:  # from rest: nothing stored
        stored = {key: np.zeros(n) for key in ensembles}
    measures = {(k, case): _measures(ensemble, stored[k, case], ensemble.energy(nodes[:, -1] * scales[k]), spec)
                for (k, case), ensemble in ensembles.items()}
    records = [{"realization": realization,
                "levels": [{case: measures[k, case][j] for case in DAMPERS} for k in range(len(levels))]}
               for j, realization in enumerate(realizations)]
    return {"index": number, "realizations": records,
            "psd": {f"{k}:{case}": {"sums": w.sums.tolist(), "segments": w.segments} for (k, case), w in welch.items()},
            "seconds": time.perf_counter() - begin}


def _measures(ensemble, before: np.ndarray, after: np.ndarray, spec: RandomSpec) -> list[dict]:
    """What the study keeps of each trajectory of ``ensemble`` over the window (see the module's
    text), from the energy it stored at the window's start (``before``, J) and now (``after``)."""
    stats, ledger, counts, failed = ensemble.stats, ensemble.ledger, ensemble.counts, ensemble.failed
    steps = spec.window_steps
    balance = ledger[:, 0] - (after - before) - ledger[:, 1:].sum(axis=1)
    return [{"ms_relative": _finite(stats[j, 0] / steps), "ms_absolute": _finite(stats[j, 1] / steps),
             "peak_relative": _finite(stats[j, 2]), "peak_absolute": _finite(stats[j, 3]), "impacts": int(counts[j]),
             "harvested": _finite(ledger[j, 4] + ledger[j, 5]), "work": _finite(ledger[j, 0]),
             "balance": _finite(balance[j]), "failed": bool(failed[j])} for j in range(ensemble.n)]


def _finite(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None
