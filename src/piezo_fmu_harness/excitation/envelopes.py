"""Modulating envelopes for earthquake-like records: the stationary acceleration ``a(t)`` times a
deterministic ``e(t)`` (a uniformly modulated process), so that the variance at ``t`` is
``e(t)^2`` times the stationary one.

Two forms, both with ``e(t) = 0`` for ``t < 0`` and a largest value of 1:

- :class:`JenningsHousnerTsai`: a quadratic rise, a plateau of strong motion and an exponential
  decay (Jennings, Housner and Tsai, 1968, *Simulated earthquake motions*, Caltech EERL);
- :class:`ShinozukaSato`: ``exp(-b1 t) - exp(-b2 t)`` normalised to a peak of 1 (Shinozuka and
  Sato, 1967, *J. Eng. Mech. Div. ASCE* 93(EM1)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .inputs import number, positive


class Envelope:
    """A modulating function of time: ``envelope(t)`` for ``t`` in s (any shape)."""

    kind = "envelope"

    def __call__(self, t) -> np.ndarray:
        raise NotImplementedError

    def parameters(self) -> dict:
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-safe: the kind and every parameter with its unit."""
        return {"kind": self.kind, "modulates": "the acceleration a(t) (its variance by e(t)^2)", **self.parameters()}


@dataclass(frozen=True)
class JenningsHousnerTsai(Envelope):
    """``e(t) = (t / t1)^2`` for ``0 <= t < t1``, 1 for ``t1 <= t <= t2``, ``exp(-c (t - t2))`` after.

    Parameters
    ----------
    t1 : float
        End of the rise, s, ``>= 0`` (0: no rise).
    t2 : float
        End of the strong motion, s, ``>= t1``.
    c : float
        Decay rate after ``t2``, 1/s, > 0.
    """

    t1: float
    t2: float
    c: float
    kind = "jennings-housner-tsai"

    def __post_init__(self):
        t1 = number("t1", self.t1, "s", 0.0, math.inf, lo_open=False)
        object.__setattr__(self, "t1", t1)
        object.__setattr__(self, "t2", number("t2", self.t2, "s", t1, math.inf, lo_open=False, why="t2 >= t1"))
        object.__setattr__(self, "c", positive("c", self.c, "1/s"))

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        rise = np.square(t / self.t1) if self.t1 > 0.0 else np.ones_like(t)
        decay = np.exp(-self.c * np.maximum(t - self.t2, 0.0))
        return np.where(t < 0.0, 0.0, np.where(t < self.t1, rise, np.where(t <= self.t2, 1.0, decay)))

    def parameters(self):
        return {"t1_s": self.t1, "t2_s": self.t2, "c_per_s": self.c}


@dataclass(frozen=True)
class ShinozukaSato(Envelope):
    """``e(t) = (exp(-b1 t) - exp(-b2 t)) / e_max`` for ``t >= 0``, ``e_max`` its value at the peak
    ``t* = ln(b2 / b1) / (b2 - b1)``.

    Parameters
    ----------
    b1 : float
        The slow (decay) rate, 1/s, > 0.
    b2 : float
        The fast (rise) rate, 1/s, ``> b1``.
    """

    b1: float
    b2: float
    kind = "shinozuka-sato"

    def __post_init__(self):
        b1 = positive("b1", self.b1, "1/s")
        object.__setattr__(self, "b1", b1)
        object.__setattr__(self, "b2", number("b2", self.b2, "1/s", b1, math.inf, why="b2 > b1"))

    @property
    def peak_time(self) -> float:
        """``t*``, s: where the envelope is 1."""
        return math.log(self.b2 / self.b1) / (self.b2 - self.b1)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        top = math.exp(-self.b1 * self.peak_time) - math.exp(-self.b2 * self.peak_time)
        tt = np.maximum(t, 0.0)
        return np.where(t < 0.0, 0.0, (np.exp(-self.b1 * tt) - np.exp(-self.b2 * tt)) / top)

    def parameters(self):
        return {"b1_per_s": self.b1, "b2_per_s": self.b2, "peak_time_s": self.peak_time}
