"""Pseudo-arclength continuation of the periodic orbits of the forced response, through the FMU.

An orbit of order ``n`` is a zero of ``G(x, lam) = P^n_lam(x) - x``: ``P`` the period map of
:mod:`piezo_fmu_harness.periodic.drive` at the section phase ``phi``, ``lam`` the continued parameter (the
frequency ratio ``w / sqrt(K/M)``, the base amplitude ``Y`` or a damper parameter). The zeros form
curves in ``(x, lam)``, and a curve may turn back in ``lam`` (a fold): a sweep in ``lam`` jumps
there, and only continuation in the arclength ``s`` passes it (Keller's pseudo-arclength, as AUTO
and COCO do it).

**Unknowns.** ``u = (z, l)``: the state scaled to ``z = (p, p'/w_n, q, q'/w_n) / L`` (``L`` the base
amplitude at the start, m) and ``l = lam / Lambda`` (``Lambda`` the parameter's scale: 1 for the
frequency ratio, the start value otherwise).

**A step.** From a point ``u_k`` with unit tangent ``t_k`` (the null vector of ``DG = [G_z, G_l]``,
oriented along the branch), the predictor is ``u_k + ds t_k``; the corrector is Newton on
``G(u) = 0, t_k . (u - u_pred) = 0`` with ``DG`` of ``u_k`` (a chord method). At the new point
``DG`` is taken by forward differences from the corrector's last residual (five runs of ``P^n``;
central differences at a seed): its ``G_z + I`` is the Jacobian of the period map, whose
eigenvalues are the Floquet multipliers, and its null vector is the next tangent. The step grows by 1.5 after an easy correction and halves after a failed one.

**Watching the multipliers.** Between two points the continuation names what changed:

- ``fold``: the parameter turns back (``dl/ds`` changes sign), where a real multiplier crosses
  +1 (``det(G_z)`` changes sign);
- ``period doubling``: a real multiplier crosses -1 (``det(G_z + 2 I)`` changes sign); the doubled
  branch is looked for there (Newton on ``P^(2n)`` from the orbit displaced along the eigenvector
  of -1) and continued in turn;
- ``Neimark-Sacker``: a complex pair crosses the unit circle;
- ``grazing``: an impact appears or disappears (the impacts per orbit change), with the smallest
  relative velocity at an impact, read from the orbit, going to zero.

**The section.** The FMU starts only with the impact mass inside the gap. When a point has it in
contact at the section, the branch moves its section to the phase of the orbit where the impact
mass is farthest from the barriers (the orbit is the same; its coordinates change) and goes on.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ...fmu import FmuRunError, Instance
from ...periodic.drive import HarmonicDrive, hermite_extrema


@dataclass(frozen=True)
class Problem:
    """What is continued (SI).

    Attributes
    ----------
    values : dict
        FMU parameters (the damper, ``voltage_model``, ``R_load``).
    parameter : str
        ``ratio`` (forcing frequency over ``sqrt(K/M)``), ``Y`` (base amplitude, m) or the name of
        a Real FMU parameter.
    bounds : tuple
        The range of the parameter; a branch stops where it leaves it.
    natural : float
        ``sqrt(K/M)``, rad/s.
    ratio : float
        The frequency ratio when it is not the parameter.
    amplitude, acceleration : float or None
        ``Y`` (m), or ``A`` (m/s^2) with ``Y = A / w^2``, when ``Y`` is not the parameter.
    samples : int
        Communication steps per forcing period.
    tolerance : float
        Corrector tolerance on ``|P^n(x) - x|``, relative to the base amplitude.
    """

    values: dict
    parameter: str
    bounds: tuple
    natural: float
    ratio: float = 1.0
    amplitude: Optional[float] = 1e-3
    acceleration: Optional[float] = None
    samples: int = 64
    tolerance: float = 1e-6

    def omega_and_amplitude(self, lam: float) -> tuple[float, float, dict]:
        """``(w, Y, values)`` at parameter value ``lam``."""
        values = dict(self.values)
        omega = (lam if self.parameter == "ratio" else self.ratio) * self.natural
        if self.parameter == "Y":
            return omega, lam, values
        if self.parameter not in ("ratio", "Y"):
            values[self.parameter] = lam
        return omega, (self.amplitude if self.amplitude is not None else self.acceleration / omega**2), values

    @property
    def scale(self) -> float:
        """``Lambda``: the parameter's scale in the arclength."""
        return 1.0 if self.parameter == "ratio" else max(abs(self.bounds[0]), abs(self.bounds[1]))


@dataclass(frozen=True)
class Settings:
    """How a branch is followed."""

    step: float = 0.05            # first arclength step (the state in units of Y)
    min_step: float = 1e-4
    max_step: float = 1.0
    max_points: int = 100         # points a direction, at most
    corrector_iterations: int = 8
    max_multiplier: float = 25.0  # a branch stops where a disturbance grows this much per orbit
    doubling_depth: int = 1       # period doublings followed from one seed


class OrbitMap:
    """``P^n`` at any parameter value, through one FMU instance (counting its runs)."""

    def __init__(self, instance: Instance, problem: Problem, phase: float, order: int):
        self.instance, self.problem, self.phase, self.order = instance, problem, phase, order
        self.evaluations = 0
        self._drives: dict = {}

    def drive(self, lam: float) -> HarmonicDrive:
        if lam not in self._drives:
            if len(self._drives) > 64:
                self._drives.clear()
            omega, amplitude, values = self.problem.omega_and_amplitude(lam)
            self._drives[lam] = HarmonicDrive(self.instance, values, omega, amplitude, self.problem.samples)
        return self._drives[lam]

    def __call__(self, x, lam: float, record: Optional[list] = None, order: Optional[int] = None):
        """``P^order(x)`` at ``lam`` (unscaled), or ``None`` if the FMU refuses the start."""
        drive = self.drive(lam)
        self.evaluations += 1
        try:
            drive.start(x, self.phase)
            return drive.advance(order or self.order, record=record)[-1]
        except FmuRunError:
            return None


@dataclass
class Point:
    """A converged point of a branch."""

    lam: float
    x: np.ndarray
    phase: float
    jacobian: np.ndarray          # DG = [G_z, G_l] (4 x 5, scaled)
    tangent: np.ndarray
    multipliers: np.ndarray
    measures: dict = field(default_factory=dict)
    iterations: int = 0

    def record(self) -> dict:
        moduli = np.abs(self.multipliers)
        return {"lam": self.lam, "state": [float(v) for v in self.x], "phase": self.phase,
                "multipliers": [[float(m.real), float(m.imag)] for m in self.multipliers],
                "max_multiplier": float(moduli.max()), "stable": bool(moduli.max() < 1.0),
                "corrector_iterations": self.iterations, **self.measures}


class Tracer:
    """Follows one branch of orbits of order ``n`` (see the module's text)."""

    def __init__(self, instance: Instance, problem: Problem, settings: Settings, phase: float, order: int,
                 length: float):
        self.problem, self.settings = problem, settings
        self.map = OrbitMap(instance, problem, phase, order)
        self.order = order
        self.length = length                                   # L, m
        wn = problem.natural
        self.S = np.array([1.0, 1.0 / wn, 1.0, 1.0 / wn]) / length  # z = x * S
        self.gap = float(problem.values.get("d", instance.model.parameters["d"].start))

    # -- scaled unknowns ---------------------------------------------------------------------------

    def unknowns(self, x, lam) -> np.ndarray:
        return np.append(np.asarray(x) * self.S, lam / self.problem.scale)

    def split(self, u) -> tuple[np.ndarray, float]:
        return u[:4] / self.S, float(u[4] * self.problem.scale)

    def residual(self, u, run: Optional[dict] = None) -> Optional[np.ndarray]:
        """``G(u)`` (scaled); with ``run`` (a dict), the run's step-by-step states and impact count
        go into it, for :meth:`measure`."""
        x, lam = self.split(u)
        record = [] if run is not None else None
        image = self.map(x, lam, record=record)
        if run is not None and image is not None:
            run.update(states=record, count=self.map.drive(lam).totals()[0])
        return None if image is None else (image - x) * self.S

    def derivative(self, u, base: Optional[np.ndarray] = None) -> Optional[np.ndarray]:
        """``DG`` (4 x 5) at ``u`` by differences of ``1e-6 max(1, |u_i|)``: forward from the
        residual ``base`` at ``u`` when given (the corrector's last), central otherwise."""
        columns = np.empty((4, 5))
        central = base is None
        for i in range(5):
            h = 1e-6 * max(1.0, abs(u[i]))
            plus = u.copy()
            plus[i] += h
            up = self.residual(plus)
            if central:
                minus = u.copy()
                minus[i] -= h
                down = self.residual(minus)
                if up is None or down is None:
                    return None
                columns[:, i] = (up - down) / (2 * h)
            else:
                if up is None or base is None:
                    return None
                columns[:, i] = (up - base) / h
        return columns

    # -- points ------------------------------------------------------------------------------------

    def point(self, u, iterations: int, previous: Optional[np.ndarray],
              base: Optional[np.ndarray] = None, run: Optional[dict] = None) -> Optional[Point]:
        """The converged point ``u`` (residual ``base`` there and its ``run``, if known) with its
        Jacobian, tangent (oriented like ``previous``), multipliers and measures."""
        x, lam = self.split(u)
        measures = self.measure(x, lam, run)
        jac = self.derivative(u, base)
        if jac is None:
            return None
        tangent = np.linalg.svd(jac)[2][-1]
        if previous is not None and float(tangent @ previous) < 0:
            tangent = -tangent
        multipliers = np.linalg.eigvals(jac[:, :4] + np.eye(4))
        multipliers = multipliers[np.argsort(-np.abs(multipliers))]
        return Point(lam, x, self.map.phase, jac, tangent, multipliers, measures, iterations)

    def measure(self, x, lam: float, run: Optional[dict] = None) -> dict:
        """The orbit's amplitude, impacts per orbit, smallest relative velocity at an impact and
        smallest clearance (m) off the impacts, from one run of ``P^n`` recorded step by step (the
        corrector's last, ``run``, when given)."""
        drive = self.map.drive(lam)
        if run is None or "states" not in run:
            run = {}
            self.residual(self.unknowns(x, lam), run)
        count = run.get("count", 0)
        states = np.array([x] + run.get("states", []))
        top, bottom = hermite_extrema(states[:, 0], states[:, 1], drive.h)
        clearance = 0.5 * self.gap - np.abs(states[:, 2] - states[:, 0])
        onsets = np.flatnonzero((clearance[:-1] > 0) & (clearance[1:] <= 0))
        velocities = np.abs(states[onsets, 3] - states[onsets, 1])
        free = clearance > 0
        peaks = [clearance[k] for k in range(1, len(clearance) - 1)
                 if free[k - 1] and free[k] and free[k + 1] and clearance[k] <= clearance[k - 1]
                 and clearance[k] <= clearance[k + 1]]
        omega, amplitude, _ = self.problem.omega_and_amplitude(lam)
        return {"amplitude": 0.5 * (top - bottom), "impacts": int(count), "order": self.order,
                "impacts_per_cycle": count / self.order, "omega": omega, "base_amplitude": amplitude,
                "min_impact_velocity": float(velocities.min()) if len(velocities) else None,
                "min_free_clearance": float(min(peaks)) if peaks else None,
                "section_clearance": float(clearance[0])}

    def rephase(self, point: Point) -> Optional[Point]:
        """The same orbit seen at the phase where the impact mass is farthest from the barriers."""
        drive = self.map.drive(point.lam)
        record: list = []
        if self.map(point.x, point.lam, record=record) is None:
            return None
        k = int(np.argmax([drive.clearance(s) for s in record]))
        self.map.phase = (self.map.phase + 2.0 * math.pi * ((k + 1) % drive.samples) / drive.samples) % (2 * math.pi)
        return self.point(self.unknowns(np.array(record[k]), point.lam), 0, None)

    # -- following a branch -----------------------------------------------------------------------

    def correct(self, predicted: np.ndarray, tangent: np.ndarray, jac: np.ndarray) -> tuple:
        """Newton (chord) on ``G = 0, t . (u - u_pred) = 0``: ``(u, iterations, G(u), run)``
        (``run``: the last run's states and impact count), ``u`` ``None`` when it fails."""
        system = np.vstack([jac, tangent])
        u = predicted.copy()
        tolerance = self.problem.tolerance * self._base_amplitude(u) / self.length
        previous = math.inf
        for iteration in range(1, self.settings.corrector_iterations + 1):
            run: dict = {}
            g = self.residual(u, run)
            if g is None:
                return None, iteration, None, None
            norm = float(np.max(np.abs(g)))
            if norm <= tolerance:
                return u, iteration, g, run
            if norm > 10 * previous:
                return None, iteration, None, None
            previous = norm
            u = u + np.linalg.solve(system, -np.append(g, tangent @ (u - predicted)))
        run = {}
        g = self.residual(u, run)
        if g is not None and np.max(np.abs(g)) <= tolerance:
            return u, self.settings.corrector_iterations, g, run
        return None, self.settings.corrector_iterations, None, None

    def _base_amplitude(self, u) -> float:
        return self.problem.omega_and_amplitude(self.split(u)[1])[1]

    def follow(self, start: Point, direction: float, stop: Callable) -> tuple[list[Point], str]:
        """Points from ``start`` along ``direction * tangent`` until the parameter leaves its
        range, ``stop(point)`` says so, the step falls below its minimum, or the cap on points."""
        s = self.settings
        points, ds = [start], s.step
        tangent = direction * start.tangent
        lo, hi = self.problem.bounds
        origin, farthest = self.unknowns(start.x, start.lam), 0.0
        while len(points) <= s.max_points:
            last = points[-1]
            if last.measures["section_clearance"] <= 0.05 * self.gap:
                moved = self.rephase(last)
                if moved is None:
                    return points, "the FMU refused the orbit's start at every phase"
                tangent = moved.tangent if float(moved.tangent[4] * tangent[4]) >= 0 else -moved.tangent
                last = moved
            u0 = self.unknowns(last.x, last.lam)
            u, iterations, g, run = self.correct(u0 + ds * tangent, tangent, last.jacobian)
            new = self.point(u, iterations, tangent, g, run) if u is not None else None
            if new is not None and float(new.tangent @ tangent) < 0.9:
                new = None  # the branch turned by more than 25 degrees in one step: too far
            if new is None:
                ds *= 0.5
                if ds < s.min_step:
                    return points, "the corrector failed (a non-smooth point: grazing or chatter)"
                continue
            points.append(new)
            tangent = new.tangent
            ds = min(s.max_step, ds * 1.5) if iterations <= 3 else (ds * 0.7 if iterations > 5 else ds)
            if not lo <= new.lam <= hi:
                return points, "left the parameter's range"
            away = float(np.linalg.norm(self.unknowns(new.x, new.lam) - origin)) if new.phase == start.phase else math.inf
            farthest = max(farthest, away if math.isfinite(away) else farthest)
            if farthest > 4 * s.step and away < max(ds, s.step):
                return points, "closed loop: the branch is an isola, back at its start"
            if float(np.max(np.abs(new.multipliers))) > s.max_multiplier:
                return points, f"a multiplier beyond {s.max_multiplier:g}: too unstable to be seen or followed"
            reason = stop(new)
            if reason:
                return points, reason
        return points, "the cap on points"
