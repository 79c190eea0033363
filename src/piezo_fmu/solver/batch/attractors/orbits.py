"""Periodic orbits on the batch engine: Newton on the period map, the verification of an orbit,
its Floquet multipliers, and the motion without impacts in closed form.

The state at the section is ``x = (p, p', q, q')`` at the start of a forcing period (phase ``phi``
of the drive); ``P^n(x)`` is the state ``n`` periods on. Distances are the largest of
``|dp|, |dp'|/w, |dq|, |dq'|/w`` (m), as in the harness.

- **Newton** on ``P^n(x) - x`` with forward-difference Jacobians, all seeds and their shifted
  copies in one ensemble per iteration, solved by least squares, a step halved while the residual
  does not fall (the map is only piecewise smooth).
- **Verification**: from ``x`` the section returns within the tolerance after ``n``, ``2n`` and
  ``3n`` periods, with the same contact onsets in every orbit.
- **Multipliers** by central differences (step ``1e-6`` of the orbit's size), checked at four
  times the step, as the harness computes them through the FMU
  (``piezo_fmu_harness.periodic.stability``).
- **Without impacts** the main mass is a linear oscillator under the hold: its periodic motion
  ``p*`` is the fixed point of the affine free-flight map of one period, and a trajectory whose
  impact mass is at rest (``q' = 0``) stays free for ever once ``q - p*(t)`` plus the largest
  departure the decaying transient can still make stays inside the gap (:func:`free_for_ever`).
  That is a proof, not an extrapolation: the transient ``e = p - p*`` obeys the free equation, so
  ``e'^2 + w_n^2 e^2`` never grows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..drive import HarmonicHold
from ..ensemble import Ensemble
from ..model import BatchModel

#: Forward-difference step of Newton's Jacobian, relative to the state's size.
NEWTON_STEP = 1e-7
#: Central-difference step of the multipliers, relative to the orbit's size, and the check's factor.
MULTIPLIER_STEP, CHECK_FACTOR = 1e-6, 4.0
#: Orbits a verification run checks.
VERIFY_ORBITS = 3


def scale_of(drive: HarmonicHold) -> np.ndarray:
    """``(1, 1/w, 1, 1/w)``: the state times it is in metres."""
    return np.array([1.0, 1.0 / drive.omega, 1.0, 1.0 / drive.omega])


@dataclass
class Orbit:
    """A verified periodic orbit of one drive (``group``), seen at the section.

    ``sections`` (order, 4) and ``sides`` (order,) are its states at the section, ``impacts`` the
    contact onsets of each of its periods, ``top``/``bottom`` the extremes of ``p`` over it (m),
    ``multipliers`` its Floquet multipliers by decreasing modulus (empty without impacts: see
    :class:`LinearOrbit`), ``largest`` the largest modulus and ``error`` its accuracy.
    """

    group: int
    order: int
    sections: np.ndarray
    sides: np.ndarray
    impacts: tuple
    top: float
    bottom: float
    multipliers: tuple = ()
    largest: float = math.nan
    error: float = math.nan
    method: str = "newton"

    @property
    def amplitude(self) -> float:
        return 0.5 * (self.top - self.bottom)

    @property
    def impacts_per_cycle(self) -> float:
        return sum(self.impacts) / self.order

    @property
    def stable(self) -> bool:
        return bool(self.largest < 1.0 - self.error)


@dataclass
class LinearOrbit:
    """The periodic motion of the main mass without impacts under one drive: ``nodes`` (N+1, 2),
    ``(p*, p*')`` at the hold nodes of one period; ``high``/``low`` (m) bound ``p*`` over the period
    from above and below (rigorously); ``top``/``bottom`` are its extremes as the harness measures
    them (the Hermite interpolant of the nodes); ``multiplier`` the modulus ``exp(-a T)`` of the
    main mass's pair (the impact mass's pair is neutral, exactly 1)."""

    nodes: np.ndarray
    high: float
    low: float
    top: float
    bottom: float
    multiplier: float = field(default=math.nan)

    @property
    def amplitude(self) -> float:
        return 0.5 * (self.top - self.bottom)


def linear_orbit(model: BatchModel, drive: HarmonicHold) -> LinearOrbit:
    """:class:`LinearOrbit` of ``drive`` (host floats, the closed form of :mod:`..model`)."""
    free = model.free
    y, v = (nodes.tolist() for nodes in drive.nodes())  # Python floats: the same arithmetic, faster
    h = drive.step
    ec, es = free.coefficients(np.array(h))
    ec, es = float(ec), float(es)

    def step(k, p, dp):
        u, du = free.apply((ec, es), p - y[k], dp - v[k])
        return u + y[k] + v[k] * h, du + v[k]

    # One period of the free map is affine: x -> A x + b; its fixed point is the orbit.
    columns = []
    for start in ([0.0, 0.0], [1.0, 0.0], [0.0, 1.0]):
        p, dp = start
        for k in range(drive.samples):
            p, dp = step(k, p, dp)
        columns.append(np.array([p, dp]))
    b = columns[0]
    A = np.stack([columns[1] - b, columns[2] - b], axis=1)
    p, dp = np.linalg.solve(np.eye(2) - A, b)
    nodes, high, low = [(p, dp)], -math.inf, math.inf
    rate = free.bound_rate
    for k in range(drive.samples):
        p1, dp1 = step(k, p, dp)
        reach = rate * math.hypot(dp - v[k], math.sqrt(free.w2) * (p - y[k])) * h * h / 8.0
        high, low = max(high, max(p, p1) + reach), min(low, min(p, p1) - reach)
        p, dp = p1, dp1
        nodes.append((p, dp))
    nodes = np.array(nodes)
    top, bottom = _hermite_range(nodes, h)
    return LinearOrbit(nodes, high, low, top, bottom, math.exp(-free.a * drive.period))


def _hermite_range(nodes: np.ndarray, h: float) -> tuple[float, float]:
    """The largest and smallest ``p`` (m) of the cubic Hermite interpolant of ``nodes`` ((N+1, 2):
    ``p, p'``, ``h`` (s) apart), ends included, with numpy's arithmetic, as the harness measures a
    motion through the FMU (``piezo_fmu_harness.periodic.drive.hermite_extrema``; the kernel's
    :func:`..kernel.periods.hermite_extremes` differs from it in the last bit, where ``s**3`` is
    rounded once here and twice there)."""
    p0, v0, p1, v1 = nodes[:-1, 0], nodes[:-1, 1], nodes[1:, 0], nodes[1:, 1]
    m0, m1 = h * v0, h * v1
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = 6.0 * (p1 - p0) - 4.0 * m0 - 2.0 * m1
    c = m0
    disc = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    quadratic = np.abs(a) > 1e-300
    safe_a = np.where(quadratic, 2.0 * a, 1.0)
    safe_b = np.where(b == 0.0, 1.0, b)
    high, low = np.maximum(p0, p1), np.minimum(p0, p1)
    for root in ((-b + disc) / safe_a, (-b - disc) / safe_a):
        s = np.where(quadratic, root, -c / safe_b)
        inside = (s > 0.0) & (s < 1.0) & ~(~quadratic & (b == 0.0))
        s = np.where(inside, s, 0.0)
        value = ((2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0
                 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1)
        high = np.where(inside, np.maximum(high, value), high)
        low = np.where(inside, np.minimum(low, value), low)
    return float(high.max()), float(low.min())


def free_for_ever(model: BatchModel, orbit: LinearOrbit, states: np.ndarray, sides: np.ndarray) -> np.ndarray:
    """Which of ``states`` (at the section, (n, 4)) never impact again: free, the impact mass at
    rest, and ``q - p*`` kept inside the gap by a margin larger than the transient can still move
    the main mass (see the module's text). A proof for each True; False says nothing. ``settle``
    runs its compiled twin at every look (:func:`.books.free_for_ever_flags`, held to this
    one by the tests)."""
    p, dp, q, dq = states.T
    w2 = model.free.w2
    e, de = p - orbit.nodes[0, 0], dp - orbit.nodes[0, 1]
    reach = np.sqrt(de * de + w2 * e * e) / math.sqrt(w2)
    hg = model.half_gap
    margin = 1e-9 * hg
    with np.errstate(invalid="ignore"):
        return ((sides == 0) & (dq == 0.0) & (q - orbit.low + reach < hg - margin)
                & (q - orbit.high - reach > -hg + margin))


class OrbitFinder:
    """Newton, verification and multipliers for one damper on the batch engine: ``drives`` the
    forcings (an orbit belongs to one, its ``group``), ``tolerance`` (m) the steady state's.

    Its ensembles march on the CPU, whatever device a study's starts march on: Newton's seeds, their
    neighbours and the checks of an orbit are thousands of ensembles of a few trajectories, and on a
    GPU each launch costs milliseconds of transfers and latency."""

    def __init__(self, model: BatchModel, drives: list, tolerance):
        self.model, self.drives = model, list(drives)
        self.tolerance = np.broadcast_to(np.asarray(tolerance, float), (len(self.drives),))
        self.cycles = 0  # start-periods marched by this finder
        self._tables = None

    @property
    def tables(self):
        """The damper and the drives packed for the compiled kernel, once."""
        if self._tables is None:
            from ..kernel import Tables
            self._tables = Tables(self.model, self.drives)
        return self._tables

    def march(self, states, sides, groups, periods: int, observe: bool = False) -> dict | None:
        """``periods`` periods from each start; None for none. Starts that the engine refuses
        (the impact mass beyond a barrier it is not in contact with) come back as NaN."""
        states, sides, groups = np.asarray(states, float), np.asarray(sides, float), np.asarray(groups, int)
        offset = states[:, 2] - states[:, 0]
        hg = self.model.half_gap
        valid = np.isfinite(states).all(axis=1) & np.where(sides == 0, np.abs(offset) <= hg, sides * offset >= hg)
        record = {"sections": np.full((periods, len(states), 4), np.nan), "sides": np.zeros((periods, len(states))),
                  "impacts": np.zeros((periods, len(states)), dtype=np.int64)}
        if observe:
            record.update(top=np.full((periods, len(states)), np.nan), bottom=np.full((periods, len(states)), np.nan))
        if valid.any():
            # ``valid`` is stricter than the ensemble's own check (no slack at the barriers)
            ens = Ensemble.checked_by_caller(self.model.params, self.model, self.tables, self.drives, states[valid],
                                             groups[valid].astype(np.int64), sides[valid])
            out = ens.advance(periods, observe=observe)
            self.cycles += periods * int(valid.sum())
            for name, values in out.items():
                record[name][:, valid] = values
        return record

    def newton(self, seeds: np.ndarray, sides: np.ndarray, groups: np.ndarray, order: int,
               iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
        """Newton on ``P^order(x) - x`` from each seed (all of one order); returns the last
        iterates and whether each converged (residual within a tenth of its tolerance)."""
        x = np.array(seeds, float)
        k = len(x)
        scale = np.array([scale_of(self.drives[g]) for g in groups])
        tol = self.tolerance[groups]
        step = None
        residual = np.full(k, np.inf)
        converged = np.zeros(k, bool)
        jac = np.zeros((k, 4, 4))
        fx = np.zeros((k, 4))
        trial = x.copy()
        amplitudes = np.array([self.drives[g].amplitude for g in groups])
        for _ in range(iterations + 1):
            size = NEWTON_STEP * np.maximum(amplitudes, np.abs(trial * scale).max(axis=1))
            copies = [trial] + [trial + np.eye(4)[i] * (size / scale[:, i])[:, None] for i in range(4)]
            images = self.march(np.concatenate(copies), np.tile(sides, 5), np.tile(groups, 5), order)["sections"][-1]
            images = images.reshape(5, k, 4)
            f_trial = images[0]
            r_trial = np.abs((f_trial - trial) * scale).max(axis=1)
            better = np.isfinite(r_trial) & (r_trial < residual)
            x[better], fx[better], residual[better] = trial[better], f_trial[better], r_trial[better]
            for i in range(4):
                column = (images[1 + i] - f_trial) * scale / size[:, None]
                jac[better, :, i] = column[better]
            converged = residual <= 0.1 * tol
            if converged.all():
                break
            new_step = np.zeros((k, 4))
            for j in range(k):
                if converged[j] or not np.isfinite(jac[j]).all():
                    continue
                if better[j] or step is None:
                    delta = np.linalg.lstsq(jac[j] - np.eye(4), -(fx[j] - x[j]) * scale[j], rcond=1e-12)[0]
                    new_step[j] = delta / scale[j]
                else:
                    new_step[j] = 0.5 * step[j]
            step = new_step
            trial = x + step
        return x, converged

    def verify(self, x: np.ndarray, sides: np.ndarray, groups: np.ndarray, order: int) -> list:
        """The orbits through ``x`` (each a fixed point of ``P^order``) that pass the verification
        run, at their least period, as :class:`Orbit` (multipliers not yet computed); None for
        those that fail."""
        periods = VERIFY_ORBITS * order
        record = self.march(x, sides, groups, periods, observe=True)
        found = []
        for j in range(len(x)):
            scale = scale_of(self.drives[groups[j]])
            returns = np.abs((record["sections"][:, j] - x[j]) * scale).max(axis=1)
            least = next((m for m in range(1, order + 1) if order % m == 0
                          and returns[m - 1::m].max() <= self.tolerance[groups[j]]), None)
            impacts = record["impacts"][:, j]
            if least is None or not (impacts.reshape(-1, least) == impacts[:least]).all():
                found.append(None)
                continue
            sections = np.concatenate([[x[j]], record["sections"][:least - 1, j]])
            orbit_sides = np.concatenate([[sides[j]], record["sides"][:least - 1, j]])
            found.append(Orbit(int(groups[j]), least, sections, orbit_sides, tuple(int(i) for i in impacts[:least]),
                               float(record["top"][:, j].max()), float(record["bottom"][:, j].min())))
        return found

    def multipliers(self, orbits: list) -> None:
        """Fill in each orbit's multipliers (central differences at ``h`` and ``4 h``)."""
        for order in sorted({o.order for o in orbits}):
            chosen = [o for o in orbits if o.order == order]
            results = []
            for factor in (1.0, CHECK_FACTOR):
                copies, sides, groups, sizes = [], [], [], []
                for o in chosen:
                    scale = scale_of(self.drives[o.group])
                    h = factor * MULTIPLIER_STEP * max(self.drives[o.group].amplitude, float(np.abs(o.sections[0] * scale).max()))
                    sizes.append((h, scale))
                    for i in range(4):
                        for sign in (1.0, -1.0):
                            copies.append(o.sections[0] + sign * np.eye(4)[i] * h / scale[i])
                            sides.append(o.sides[0])
                            groups.append(o.group)
                images = self.march(np.array(copies), np.array(sides), np.array(groups), order)["sections"][-1]
                images = images.reshape(len(chosen), 4, 2, 4)
                spectra = []
                for j, (h, scale) in enumerate(sizes):
                    J = np.stack([(images[j, i, 0] - images[j, i, 1]) * scale / (2.0 * h) for i in range(4)], axis=1)
                    values = np.linalg.eigvals(J) if np.isfinite(J).all() else np.full(4, np.nan)
                    spectra.append(sorted(values, key=lambda mu: -abs(mu)))
                results.append(spectra)
            for o, fine, coarse in zip(chosen, *results):
                o.multipliers = tuple(complex(mu) for mu in fine)
                o.largest = float(abs(fine[0]))
                o.error = abs(o.largest - float(abs(coarse[0])))
