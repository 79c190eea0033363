"""The stability of a periodic orbit: its Floquet multipliers, through the FMU.

An orbit of order ``n`` is a fixed point ``x*`` of the ``n``-th power of the period map,
``P^n(x*) = x*`` (:mod:`piezo_fmu_harness.periodic.drive`). Its Floquet multipliers are the eigenvalues of
the Jacobian ``J = dP^n/dx`` at ``x*``. A small departure ``e`` from the orbit becomes ``J e`` one
orbit later, so the orbit is stable when every multiplier lies inside the unit circle, and a
multiplier ``mu`` outside it makes a departure grow by ``|mu|`` per orbit.

**The Jacobian** is taken by central differences through the FMU: each column from two runs of
``P^n``, started ``+h`` and ``-h`` along one coordinate of the scaled state
``(p, p'/w, q, q'/w)``. The step is relative to the orbit's size, ``h = STEP * max(Y, |x|)``
(1e-6: the map's rounding, amplified over an orbit, stays below 1e-9 of a column, and its
curvature below 1e-10). The step is checked: the multipliers are computed again at ``4 h``, and
the difference of the two largest moduli is reported as ``multiplier_error``. A vibro-impact map
is only piecewise smooth, so a large error says that the orbit is close to grazing, where the
multipliers are not defined.

**The neutral pair.** When the orbit makes no impact, the impact mass flies freely, apart from the
main mass: ``(q, q') -> (q + q' n T, q')``. That block of ``J`` is ``[[1, nT], [0, 1]]``, a pair of
multipliers exactly 1 in a Jordan block, which finite differences would split into ``1 +- O(sqrt
of the rounding)``. The pair is neutral (a family of orbits, one for each position of the resting
impact mass), not unstable: it is set to exactly 1, reported as ``neutral``, and left out of the
largest modulus and the verdict, which then come from the main mass's block ``J[:2, :2]`` alone.

**The verdict** is ``stable`` when the largest modulus (the neutral pair left out) is below 1 by
more than its error, ``unstable`` when it is above 1 by more than its error, ``marginal``
otherwise, and ``unchecked`` when the FMU cannot be started anywhere on the orbit (the impact mass
in contact all along it); only a ``stable`` orbit is ever the response at a frequency.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

#: Central-difference step, relative to ``max(Y, |x|)`` of the scaled state.
STEP = 1e-6
#: The second step, as a multiple of the first, for the error estimate.
CHECK_FACTOR = 4.0


@dataclass(frozen=True)
class Floquet:
    """The Floquet multipliers of one orbit.

    Attributes
    ----------
    multipliers : tuple of complex
        All four, by decreasing modulus; the neutral pair (if any) as exactly ``1``.
    neutral : int
        How many of them are the free impact mass's neutral pair (2 or 0).
    largest : float
        The largest modulus, the neutral pair left out.
    error : float
        ``|largest(h) - largest(4 h)|``: the accuracy of ``largest``.
    vector : numpy.ndarray
        The (real part of the) eigenvector of the largest multiplier, in the unscaled state
        ``(p, p', q, q')``, normalised so that its scaled largest component is 1.
    step : float
        The central-difference step ``h`` (m, in the scaled state).
    """

    multipliers: tuple
    neutral: int
    largest: float
    error: float
    vector: np.ndarray
    step: float

    @classmethod
    def unchecked(cls) -> "Floquet":
        """An orbit whose multipliers cannot be computed: the impact mass is in contact all along
        it, and the FMU starts only with it inside the gap. Never taken for stable."""
        nan = float("nan")
        return cls((complex(nan, nan),) * 4, 0, nan, nan, np.zeros(4), nan)

    @property
    def margin(self) -> float:
        """``1 - largest``: how far inside the unit circle the orbit's worst multiplier lies."""
        return 1.0 - self.largest

    @property
    def verdict(self) -> str:
        if not np.isfinite(self.largest):
            return "unchecked"
        if self.largest < 1.0 - self.error:
            return "stable"
        if self.largest > 1.0 + self.error:
            return "unstable"
        return "marginal"

    @property
    def stable(self) -> bool:
        return self.verdict == "stable"

    def to_record(self) -> dict:
        """JSON-safe fields of a point's record."""
        return {"multipliers": [[float(mu.real), float(mu.imag)] for mu in self.multipliers],
                "neutral_multipliers": self.neutral, "max_multiplier": self.largest,
                "stability_margin": self.margin, "multiplier_error": self.error, "verdict": self.verdict,
                "stable": self.stable}


def jacobian(period_map: Callable, x: np.ndarray, scale: np.ndarray, step: float) -> Optional[np.ndarray]:
    """``dP^n/dx`` in the scaled state by central differences of step ``step``; a column whose
    ``-h`` start the FMU refuses (the impact mass outside the gap) falls back to a forward
    difference. ``None`` if neither side of some column can be run."""
    x = np.asarray(x, float)
    columns = np.empty((4, 4))
    for i in range(4):
        sides = {}
        for sign in (1.0, -1.0):
            shifted = x.copy()
            shifted[i] += sign * step / scale[i]
            value = period_map(shifted)
            if value is not None:
                sides[sign] = np.asarray(value) * scale
        if len(sides) == 2:
            columns[:, i] = (sides[1.0] - sides[-1.0]) / (2.0 * step)
        elif sides:
            centre = period_map(x)
            if centre is None:
                return None
            sign, value = next(iter(sides.items()))
            columns[:, i] = sign * (value - np.asarray(centre) * scale) / step
        else:
            return None
    return columns


def _spectrum(matrix: np.ndarray, neutral: bool) -> tuple[list, np.ndarray]:
    """The multipliers by decreasing modulus and the eigenvector of the largest non-neutral one
    (in the scaled state)."""
    if neutral:
        values, vectors = np.linalg.eig(matrix[:2, :2])
        order = np.argsort(-np.abs(values))
        vector = np.zeros(4, dtype=complex)
        vector[:2] = vectors[:, order[0]]
        return [complex(v) for v in values[order]], vector
    values, vectors = np.linalg.eig(matrix)
    order = np.argsort(-np.abs(values))
    return [complex(v) for v in values[order]], vectors[:, order[0]]


def floquet(period_map: Callable, x, scale: np.ndarray, size: float, neutral: bool) -> Optional[Floquet]:
    """The Floquet multipliers of the orbit through ``x`` (a fixed point of ``period_map``).

    Parameters
    ----------
    period_map : callable
        ``x -> P^n(x)`` (unscaled state), or ``None`` when the FMU refuses the start.
    x : array_like
        The orbit's state at the section, ``(p, p', q, q')`` (m, m/s).
    scale : numpy.ndarray
        ``(1, 1/w, 1, 1/w)``: the scaled state is ``x * scale`` (m).
    size : float
        The size the step is relative to: ``max(Y, |x * scale|)`` (m).
    neutral : bool
        The orbit makes no impact: the impact mass's pair is neutral (see the module's text).

    Returns
    -------
    Floquet or None
        ``None`` when the FMU refuses the starts around ``x`` on both sides.
    """
    h = STEP * size
    results = []
    for step in (h, CHECK_FACTOR * h):
        matrix = jacobian(period_map, x, scale, step)
        if matrix is None:
            return None
        results.append(_spectrum(matrix, neutral))
    (values, vector), (check, _) = results
    largest = float(abs(values[0]))
    error = abs(largest - float(abs(check[0])))
    multipliers = values + ([1.0 + 0.0j, 1.0 + 0.0j] if neutral else [])
    multipliers = sorted(multipliers, key=lambda mu: -abs(mu))
    real = np.real(vector) if np.max(np.abs(np.real(vector))) >= np.max(np.abs(np.imag(vector))) else np.imag(vector)
    real = real / real[int(np.argmax(np.abs(real)))]
    return Floquet(tuple(multipliers), 2 if neutral else 0, largest, error, real / scale, h)


@dataclass
class Orbit:
    """A verified periodic orbit with its stability and measures."""

    state: np.ndarray
    phase: float
    order: int
    sections: list  # (phase, the orbit's states at that phase), for each section it was seen at
    return_error: float
    method: str
    floquet: Floquet
    checked_at: tuple  # (state, phase) where the multipliers were computed
    measures: dict = field(default_factory=dict)

    def record(self) -> dict:
        """JSON-safe: where the orbit is, its measures and its multipliers."""
        return {"order": self.order, "state": [float(v) for v in self.state], "phase": float(self.phase),
                "method": self.method, "return_error": self.return_error, **self.measures, **self.floquet.to_record()}
