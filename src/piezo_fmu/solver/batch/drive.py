"""Harmonic base motion as the FMUs receive it: a first-order hold of ``N`` nodes a period.

The base moves as ``y = Y sin(w t + phi)``. An FMU holds its inputs as a first-order hold over
each communication step, so what a host gives it, and what the batch engine marches, is the
continuous piecewise-linear base through the nodes ``y_k = A sin(phi + 2 pi k / N)`` with slopes
``(y_{k+1} - y_k) / h``, ``h = T / N``. The fundamental of that interpolant is ``A sinc^2(pi/N)``,
so the nodes take ``A = Y / sinc^2(pi/N)`` and the base's fundamental is exactly
``Y sin(w t + phi)``; its other harmonics lie at ``(kN +- 1) w`` with amplitudes
``Y / (kN +- 1)^2`` (2.5e-4 Y at N = 64). This is the drive of the harness
(``piezo_fmu_harness.periodic.drive``), computed the same way to the bit, so the batch engine and
an FMU marched by the harness see the same base.

Between two nodes the base is a ramp, and in coordinates relative to it the motion of every phase
is linear and unforced (``docs/model.md`` sections 2-3): that is what makes each step exact in
closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Nodes a forcing period, at least (the harness's ``--samples`` has the same floor).
MIN_SAMPLES = 16


def sinc(x: float) -> float:
    return 1.0 if x == 0.0 else math.sin(x) / x


@dataclass(frozen=True)
class HarmonicHold:
    """The base of one forcing: ``y = Y sin(w t + phi)`` as a first-order hold of ``samples``
    nodes a period (see the module's text).

    Attributes
    ----------
    omega : float
        Forcing frequency ``w``, rad/s (> 0).
    amplitude : float
        Base displacement amplitude ``Y``, m (>= 0).
    phase : float
        Forcing phase ``phi`` at ``t = 0``, rad.
    samples : int
        Nodes (communication steps) a forcing period, >= 16.
    """

    omega: float
    amplitude: float
    phase: float = 0.0
    samples: int = 64

    def __post_init__(self):
        checks = (("omega", self.omega, "rad/s", math.isfinite(self.omega) and self.omega > 0, "(0, inf)"),
                  ("amplitude", self.amplitude, "m", math.isfinite(self.amplitude) and self.amplitude >= 0,
                   "[0, inf)"),
                  ("phase", self.phase, "rad", math.isfinite(self.phase), "(-inf, inf)"))
        for name, value, unit, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name} = {value!r} {unit} is out of range; allowed range {allowed} {unit}")
        if isinstance(self.samples, bool) or int(self.samples) != self.samples or self.samples < MIN_SAMPLES:
            raise ValueError(f"samples = {self.samples!r} nodes a period is out of range; allowed range "
                             f"[{MIN_SAMPLES}, inf) (whole numbers)")

    @property
    def period(self) -> float:
        """s: ``2 pi / w``."""
        return 2.0 * math.pi / self.omega

    @property
    def step(self) -> float:
        """s: the length ``h`` of one hold step, ``T / N``."""
        return self.period / self.samples

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """The node values ``y_k`` (m, ``N + 1`` of them, the last one a period on) and the slopes
        ``v_k`` (m/s, ``N``) of one period, as the harness's drive computes them."""
        n = int(self.samples)
        scaled = self.amplitude / sinc(math.pi / n) ** 2
        y = [scaled * math.sin(self.phase + 2.0 * math.pi * k / n) for k in range(n + 1)]
        h = self.step
        return np.array(y), np.array([(y[k + 1] - y[k]) / h for k in range(n)])
