"""What trajectories of the batch engine do over a window: the measures of a motion that is not
periodic (its largest Lyapunov exponent with a 95% interval, the modulation of its amplitude, its
impacts, how much of its section's spectrum lies in a few lines), and the section states a start
passes through (its track).

:func:`measure` marches the pairs; :func:`statistics` computes the measures from what the march
logged, period by period: the log stretch of each pair, the extremes of ``p``, the impacts and the
section samples.

**The exponent's interval.** The per-period log stretches of one trajectory are correlated, so the
interval is that of batch means: the window cut into :data:`BATCHES` consecutive batches, the
exponent the mean of their means, and the 95% interval Student's t over them.

**The line share.** A quasi-periodic motion crosses the section on an invariant circle: the
section samples of ``p`` are a few lines (the rotation and its harmonics); a chaotic one spreads
over a band. The share of the variance of the samples (Hann window, mean removed) within
+-``LINE_BINS`` bins of the :data:`LINES` largest peaks of the periodogram is the line share: near
1 for a line spectrum, well below it for a broad one."""

from __future__ import annotations

import numpy as np

from ..drive import HarmonicHold
from ..ensemble import Ensemble

#: The companion of the Lyapunov exponent, relative to the state's size.
COMPANION = 1e-8
#: Batches of the exponent's interval.
BATCHES = 10
#: Peaks of the line share, and the bins on either side of each that it counts.
LINES, LINE_BINS = 5, 2
#: Student's t at 97.5% for 1 to 30 degrees of freedom.
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
         2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042)


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


MEASURES = ("exponent", "exponent_low", "exponent_high", "modulation", "impacts_per_cycle", "amplitude",
            "amplitude_min", "amplitude_max", "line_share")


def empty_measures(n: int) -> dict:
    return {name: np.full(n, np.nan) for name in MEASURES}


def measure(ens: Ensemble, ids, measures: dict, scales, periods: int, finder) -> tuple:
    """Lyapunov exponent, modulation, impacts, amplitudes and line share of the trajectories left,
    written into ``measures`` (:func:`statistics`): each is marched beside a companion ``COMPANION``
    of its size away, brought back to that distance (along the same direction) after every period
    (:meth:`Ensemble.separate`). Returns their states and phases at the end, and ``p`` at each
    section of the window."""
    m = len(ids)
    states, groups = ens.states, ens.group
    direction = np.random.default_rng(0).standard_normal(4)
    direction /= np.linalg.norm(direction)
    scale = scales[groups]
    delta = COMPANION * np.maximum(np.abs(states * scale).max(axis=1), 1e-300)
    out = ens.separate(direction[None] * delta[:, None] / scale, scale, delta, periods)
    finder.cycles += 2 * m * periods
    for name, values in statistics(out["logs"], out["top"], out["bottom"], out["impacts"], out["samples"]).items():
        measures[name][ids] = values
    return ens.states, ens.sides, out["samples"].T


def statistics(logs, tops, bottoms, counts, samples) -> dict:
    """The measures (:data:`MEASURES`) of ``m`` trajectories from what a window of ``periods``
    logged, each a ``(periods, m)`` array: the log stretch of the pair in each period, the largest
    and smallest ``p`` (m), the impacts, and ``p`` at each section. The exponent is per period,
    with its 95% interval (batch means); see the module's text."""
    logs = np.asarray(logs, float)
    periods, m = logs.shape
    exponent = logs.mean(axis=0)
    batches = min(BATCHES, periods)
    if batches >= 2:
        cut = periods // batches * batches
        means = logs[periods - cut:].reshape(batches, cut // batches, m).mean(axis=1)
        half = _T975[batches - 2] * means.std(axis=0, ddof=1) / np.sqrt(batches)
    else:
        half = np.full(m, np.nan)
    swings = 0.5 * (np.asarray(tops) - np.asarray(bottoms))
    largest = swings.max(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        modulation = np.where(largest > 0, (largest - swings.min(axis=0)) / largest, 0.0)
    return {"exponent": exponent, "exponent_low": exponent - half, "exponent_high": exponent + half,
            "modulation": modulation, "impacts_per_cycle": np.asarray(counts).mean(axis=0),
            "amplitude": 0.5 * (np.asarray(tops).max(axis=0) - np.asarray(bottoms).min(axis=0)),
            "amplitude_min": swings.min(axis=0), "amplitude_max": largest, "line_share": line_share(samples)}


def line_share(samples) -> np.ndarray:
    """The share of the variance of each column of ``samples`` ((periods, m)) in a few lines of its
    periodogram (see the module's text); NaN for a window too short (under 16 periods) and 1 for a
    constant one."""
    x = np.asarray(samples, float)
    periods, m = x.shape
    if periods < 16:
        return np.full(m, np.nan)
    x = (x - x.mean(axis=0)) * np.hanning(periods)[:, None]
    power = np.abs(np.fft.rfft(x, axis=0)) ** 2
    power[0] = 0.0
    total = power.sum(axis=0)
    share = np.ones(m)
    bins = power.shape[0]
    for j in np.flatnonzero(total > 0):
        p = power[:, j].copy()
        kept = 0.0
        for _ in range(LINES):
            k = int(p.argmax())
            lo, hi = max(k - LINE_BINS, 0), min(k + LINE_BINS + 1, bins)
            kept += p[lo:hi].sum()
            p[lo:hi] = 0.0
        share[j] = kept / total[j]
    return share
