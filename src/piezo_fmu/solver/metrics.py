"""Running metrics of a run (docs/model.md section 6) and perfectibility over a sweep (eq. 31)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Metrics:
    """Metrics of a run so far, SI.

    Attributes
    ----------
    impact_count : contact onsets so far.
    completed_impacts : contacts that have ended; ``V_rms`` is over these.
    DI : m/s, damping inclination (eq. 29) from the first two positive maxima of ``p``;
        NaN until two exist.
    DI_ls : m/s, minus the least-squares slope of the positive maxima of ``p`` that follow
        an impact (a robust companion of eq. 29); NaN until two such maxima exist.
    V_rms : V, RMS of the per-impact peak voltages (eq. 30); 0 before the first completed contact.
    P_ave : W, ``V_rms**2 / R_load``.
    last_impact_voltage : V, peak voltage of the last completed contact; 0 before it.
    t1, P1, t2, P2 : s and m, the maxima used by eq. 29 (NaN until found).
    """

    impact_count: int
    completed_impacts: int
    DI: float
    DI_ls: float
    V_rms: float
    P_ave: float
    last_impact_voltage: float
    t1: float
    P1: float
    t2: float
    P2: float

    def as_dict(self) -> dict:
        return asdict(self)


class MetricAccumulators:
    """The sums behind :class:`Metrics`; a handful of numbers, whatever the run length."""

    FIELDS = ("impact_count", "completed", "sum_v2", "last_voltage", "first_maxima",
              "impacts_since_maximum", "ls_n", "ls_t", "ls_p", "ls_tt", "ls_tp")

    def __init__(self) -> None:
        self.impact_count = 0
        self.completed = 0
        self.sum_v2 = 0.0
        self.last_voltage = 0.0
        self.first_maxima: list[list[float]] = []
        self.impacts_since_maximum = 0
        self.ls_n = 0
        self.ls_t = self.ls_p = self.ls_tt = self.ls_tp = 0.0

    def impact_started(self) -> None:
        self.impact_count += 1
        self.impacts_since_maximum += 1

    def impact_ended(self, voltage: float) -> None:
        self.completed += 1
        self.sum_v2 += voltage * voltage
        self.last_voltage = voltage

    def maximum(self, t: float, p: float) -> None:
        """A maximum of the main-mass displacement ``p`` (m) at time ``t`` (s)."""
        if p <= 0.0:
            return
        if len(self.first_maxima) < 2:
            self.first_maxima.append([t, p])
        if self.impacts_since_maximum:
            self.ls_n += 1
            self.ls_t += t
            self.ls_p += p
            self.ls_tt += t * t
            self.ls_tp += t * p
        self.impacts_since_maximum = 0

    def metrics(self, R_load: float) -> Metrics:
        v_rms = math.sqrt(self.sum_v2 / self.completed) if self.completed else 0.0
        (t1, P1), (t2, P2) = (self.first_maxima + [[math.nan, math.nan]] * 2)[:2]
        di = (P1 - P2) / (t2 - t1) if len(self.first_maxima) == 2 else math.nan
        di_ls = math.nan
        if self.ls_n >= 2:
            denominator = self.ls_n * self.ls_tt - self.ls_t**2
            if denominator > 0:
                di_ls = -(self.ls_n * self.ls_tp - self.ls_t * self.ls_p) / denominator
        return Metrics(
            impact_count=self.impact_count, completed_impacts=self.completed, DI=di, DI_ls=di_ls,
            V_rms=v_rms, P_ave=v_rms**2 / R_load, last_impact_voltage=self.last_voltage,
            t1=t1, P1=P1, t2=t2, P2=P2,
        )

    def to_dict(self) -> dict:
        data = {name: getattr(self, name) for name in self.FIELDS}
        data["first_maxima"] = [list(m) for m in self.first_maxima]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "MetricAccumulators":
        acc = cls()
        for name in cls.FIELDS:
            setattr(acc, name, data[name])
        acc.first_maxima = [list(m) for m in acc.first_maxima]
        return acc


def perfectibility(V_rms, DI, WF1: float = 0.5, WF2: float = 0.5):
    """Perfectibility (eq. 31) in percent over a sweep of ``V_rms`` (V) and ``DI`` (m/s) values.

    ``100 (WF1 V_rms / max V_rms + WF2 DI / max DI)``; NaN entries are ignored in the maxima.
    """
    v = np.asarray(V_rms, dtype=float)
    di = np.asarray(DI, dtype=float)
    return 100.0 * (WF1 * v / np.nanmax(v) + WF2 * di / np.nanmax(di))
