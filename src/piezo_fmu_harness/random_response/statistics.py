"""The estimates of a random-excitation study and their 95% intervals, over realizations.

Each realization gives one value of each measure (its mean square over the window, its largest
excursion, its impacts, its harvested energy); the realizations are independent, so:

- a **mean** has the Student-t interval of the realizations' values (:func:`mean_interval`);
- an **RMS** over the ensemble, ``sqrt(mean(ms))``, has the interval of the mean square carried by the
  square root (:func:`rms_interval`);
- the **ratio** of two RMS values from the same inputs (with and without the damper), ``sqrt(mean(a)
  / mean(b))``, has the delta method's interval of the log of a ratio of means with the pairs'
  covariance (:func:`paired_ratio`): the pairing removes the inputs' own scatter from the ratio;
- a **quantile** of the values (the median or the 95th percentile of the peaks) has the
  distribution-free interval of order statistics (:func:`quantile_interval`).

:class:`Welch` is the response's power spectral density, one-sided per Hz (scipy's ``welch`` with
``scaling="density"``), accumulated block by block over many realizations with each segment at a
fixed place in its record, so that it does not depend on how the records are cut.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

#: The intervals' level.
LEVEL = 0.95


def mean_interval(values) -> tuple[float, float, float]:
    """``(mean, low, high)``: the mean of ``values`` and its Student-t interval (NaN with fewer than two)."""
    values = np.asarray(values, float)
    mean = float(values.mean())
    if len(values) < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.5 + LEVEL / 2, len(values) - 1) * values.std(ddof=1) / math.sqrt(len(values)))
    return mean, mean - half, mean + half


def rms_interval(mean_squares) -> tuple[float, float, float]:
    """``(rms, low, high)``: ``sqrt(mean(mean_squares))`` and the interval of the mean square, square-rooted."""
    mean, low, high = mean_interval(mean_squares)
    return math.sqrt(mean), math.sqrt(max(low, 0.0)) if low == low else math.nan, \
        math.sqrt(high) if high == high else math.nan


def paired_ratio(a, b) -> tuple[float, float, float]:
    """``(ratio, low, high)``: ``sqrt(mean(a) / mean(b))`` for the paired mean squares ``a`` and ``b`` (one
    pair a realization), with the delta method's interval of its log from the pairs' variances and
    covariance, Student's quantile for ``n - 1`` degrees of freedom in place of the normal one (the
    same for a thousand pairs; honest for a few)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = len(a)
    ma, mb = float(a.mean()), float(b.mean())
    ratio = math.sqrt(ma / mb)
    if n < 2:
        return ratio, math.nan, math.nan
    cov = np.cov(a, b, ddof=1)
    # var(log(ma / mb)) = var(ma)/ma^2 - 2 cov/(ma mb) + var(mb)/mb^2; the log of the RMS ratio is half of it
    var = (cov[0, 0] / ma**2 - 2.0 * cov[0, 1] / (ma * mb) + cov[1, 1] / mb**2) / n
    half = 0.5 * float(stats.t.ppf(0.5 + LEVEL / 2, n - 1)) * math.sqrt(max(var, 0.0))
    return ratio, ratio * math.exp(-half), ratio * math.exp(half)


def quantile_interval(values, q: float) -> tuple[float, float, float]:
    """``(value, low, high)``: the ``q`` quantile of ``values`` and the order statistics that bracket it
    with at least 95% confidence (binomial; widened on one side where the other meets the extreme
    value). Where even the smallest and the largest value bracket
    it with less (too few values: a single record, or fewer than 59 for the 95th percentile), the
    bounds are NaN: no interval, rather than one that claims more than it holds."""
    ordered = np.sort(np.asarray(values, float))
    n = len(ordered)
    value = float(np.quantile(ordered, q))
    first = max(int(stats.binom.ppf((1 - LEVEL) / 2, n, q)), 1)  # order statistics, counted from 1
    last = min(int(stats.binom.ppf(0.5 + LEVEL / 2, n, q)) + 1, n)
    coverage = lambda: stats.binom.cdf(last - 1, n, q) - stats.binom.cdf(first - 1, n, q)  # noqa: E731
    while coverage() < LEVEL and (first > 1 or last < n):  # clamped at one end: widen the other
        first, last = max(first - 1, 1), min(last + 1, n)
    if coverage() < LEVEL:
        return value, math.nan, math.nan
    return value, float(ordered[first - 1]), float(ordered[last - 1])


class Welch:
    """The one-sided power spectral density (unit^2/Hz) of records sampled every ``step`` (s), averaged
    over Hann-windowed segments of ``length`` samples overlapping by half and over records: fed
    block by block (:meth:`add`, each record's samples in order, ``(records, samples)``), each
    record's segments start at multiples of ``length / 2`` from its first sample, whatever the blocks."""

    def __init__(self, step: float, length: int, records: int):
        self.step, self.length, self.records = float(step), int(length), int(records)
        self.window = np.hanning(self.length + 1)[:-1]  # periodic, as scipy's "hann"
        self._buffer = np.empty((self.records, 0))
        self.sums = np.zeros(self.length // 2 + 1)
        self.segments = 0

    @property
    def frequencies(self) -> np.ndarray:
        """Hz."""
        return np.fft.rfftfreq(self.length, self.step)

    def add(self, samples) -> None:
        """The next samples of every record, ``(records, count)``."""
        data = np.hstack([self._buffer, np.asarray(samples, float)])
        hop = self.length // 2
        starts = range(0, data.shape[1] - self.length + 1, hop)
        for start in starts:
            segment = data[:, start:start + self.length]
            segment = (segment - segment.mean(axis=1, keepdims=True)) * self.window
            self.sums += (np.abs(np.fft.rfft(segment, axis=1)) ** 2).sum(axis=0)
            self.segments += self.records
        kept = (len(starts) * hop) if len(starts) else 0
        self._buffer = data[:, kept:]

    def density(self) -> np.ndarray:
        """The PSD (unit^2/Hz) at :attr:`frequencies`, as ``scipy.signal.welch(..., scaling="density")``."""
        scale = 1.0 / (self.step ** -1 * (self.window ** 2).sum())
        psd = self.sums / max(self.segments, 1) * scale
        psd[1:-1 if self.length % 2 == 0 else None] *= 2.0
        return psd


def welch_density(sums, segments: int, step: float, length: int) -> np.ndarray:
    """The PSD (unit^2/Hz) of :class:`Welch` sums of ``segments`` segments of ``length`` samples
    ``step`` (s) apart (as :meth:`Welch.density`): several :class:`Welch` es' sums and counts add."""
    welch = Welch(step, length, 0)
    welch.sums, welch.segments = np.asarray(sums, float), int(segments)
    return welch.density()
