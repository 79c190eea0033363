"""What trajectories of the batch engine do over a window: the measures of a motion that is not
periodic (its largest Lyapunov exponent, the modulation of its amplitude, its impacts), and the
section states a start passes through (its track)."""

from __future__ import annotations

import numpy as np

from .drive import HarmonicHold
from .ensemble import Ensemble

#: The companion of the Lyapunov exponent, relative to the state's size.
COMPANION = 1e-8


def tracks(params, drives, starts, groups, periods, device: str = "cpu") -> list[list[list[float]]]:
    """The section states of each start (``(n, 4)``, free) over its first ``periods[j]`` periods,
    JSON-safe: what a check through the FMU compares its own trajectory with."""
    drives = [drives] if isinstance(drives, HarmonicHold) else list(drives)
    periods = [int(k) for k in periods]
    if not periods:
        return []
    ens = Ensemble(params, drives, np.asarray(starts, float), np.asarray(groups, int), device=device)
    sections = ens.advance(max(max(periods), 1))["sections"]
    return [[[float(v) for v in row] for row in sections[:k, j]] for j, k in enumerate(periods)]


def empty_measures(n: int) -> dict:
    return {name: np.full(n, np.nan) for name in ("exponent", "modulation", "impacts_per_cycle", "amplitude",
                                                  "amplitude_min", "amplitude_max")}


def measure(ens: Ensemble, ids, measures: dict, scales, periods: int, finder) -> tuple:
    """Lyapunov exponent, modulation, impacts and amplitudes of the trajectories left, written into
    ``measures``: each is marched beside a companion ``COMPANION`` of its size away, brought back to
    that distance (along the same direction) after every period (:meth:`Ensemble.separate`). Returns
    their states and phases at the end, and ``p`` at each section of the window."""
    m = len(ids)
    states, groups = ens.states, ens.group
    direction = np.random.default_rng(0).standard_normal(4)
    direction /= np.linalg.norm(direction)
    scale = scales[groups]
    delta = COMPANION * np.maximum(np.abs(states * scale).max(axis=1), 1e-300)
    out = ens.separate(direction[None] * delta[:, None] / scale, scale, delta, periods)
    finder.cycles += 2 * m * periods
    tops, bottoms = out["top"], out["bottom"]
    swings = 0.5 * (tops - bottoms)
    largest = swings.max(axis=0)
    measures["exponent"][ids] = out["logs"].sum(axis=0) / periods
    with np.errstate(divide="ignore", invalid="ignore"):
        measures["modulation"][ids] = np.where(largest > 0, (largest - swings.min(axis=0)) / largest, 0.0)
    measures["impacts_per_cycle"][ids] = out["impacts"].mean(axis=0)
    measures["amplitude"][ids] = 0.5 * (tops.max(axis=0) - bottoms.min(axis=0))
    measures["amplitude_min"][ids] = swings.min(axis=0)
    measures["amplitude_max"][ids] = largest
    return ens.states, ens.sides, out["samples"].T
