"""Many trajectories of one damper marched together, hold step by hold step, exactly.

An :class:`Ensemble` holds the state of ``n`` trajectories (``p, p', q, q'``, the phase, and the
patch voltages under ``voltage_model = 2``) as arrays, each under its own harmonic base
(:class:`~.drive.HarmonicHold`, all with the same nodes a period). A hold step is taken for all of
them at once:

1. **Free flight with no contact possible.** The closed form of free flight (:mod:`.phases`)
   takes every free trajectory to the end of the step. The impact mass's distance from the
   barriers is at most its larger value at the two ends plus ``B h^2 / 8`` in between (``B`` the
   bound on its curvature): a trajectory that stays clear of both barriers by that margin is done.
2. **The others** (in contact, or near a barrier) go through events one at a time: the next switch
   is located on the closed form (:mod:`.events`), the state is moved there, the momentum-exact
   switch rule applied (docs/model.md section 3), and so on to the end of the step. No Python loop
   runs over trajectories: each round works on the arrays of those still inside the step.

The base is the FMUs' first-order hold (:mod:`.drive`), so an ensemble marches the motion an FMU
marched by the harness shows, and agrees with the scalar core (``piezo_fmu.solver.Simulator``) and
the FMUs to rounding on orbits that are stable.
"""

from __future__ import annotations

import numpy as np

from ...model.parameters import Parameters
from .drive import HarmonicHold
from .events import EPS, NOISE_ULPS, ZERO
from .namespace import namespace, to_numpy
from .phases import BatchModel
from .rounds import event_rounds

class Ensemble:
    """``n`` trajectories of the damper ``params`` under harmonic base motion (see the module's text).

    Parameters
    ----------
    params : Parameters
        The damper (its initial-state fields are not used).
    drives : HarmonicHold or sequence of them
        The base motions; all with the same ``samples``.
    states : array_like, (n, 4)
        ``(p, p', q, q')`` of each trajectory at ``t = 0`` (m, m/s), the impact mass within the gap.
    group : array_like of int, (n,), optional
        The drive of each trajectory (index into ``drives``); all the first by default.
    sides : array_like of int, (n,), optional
        The phase of each start: 0 free (the default), +1 or -1 in contact with that barrier (the
        impact mass then at or beyond it: ``s (q - p) >= d/2``).
    volts : array_like, (2, n), optional
        Under ``voltage_model = 2``: the patch voltages (V) of the left and right barriers at the
        start (0 by default, as in the FMUs).
    device : str
        "cpu" (numpy) or "gpu" (CuPy), :func:`~.namespace.namespace`.
    model : BatchModel, optional
        ``BatchModel.of(params)``, when the caller has it already.
    """

    def __init__(self, params: Parameters, drives, states, group=None, sides=None, volts=None, device: str = "cpu",
                 model: BatchModel | None = None):
        self.xp = xp = namespace(device)
        self.device = device
        self.model = model = model or BatchModel.of(params)
        self.params = params
        drives = [drives] if isinstance(drives, HarmonicHold) else list(drives)
        if not drives:
            raise ValueError("drives: none given; allowed: one HarmonicHold or more")
        samples = {drive.samples for drive in drives}
        if len(samples) != 1:
            raise ValueError(f"drives: samples {sorted(samples)} differ; allowed: one number of nodes a period for all")
        self.drives, self.samples = drives, samples.pop()
        states = np.asarray(states, dtype=float)
        if states.ndim != 2 or states.shape[1] != 4:
            raise ValueError(f"states: shape {states.shape}; allowed shape (n, 4): p, p', q, q' of each trajectory")
        n = states.shape[0]
        sides = np.zeros(n) if sides is None else np.asarray(sides, dtype=float)
        if sides.shape != (n,) or not np.isin(sides, (-1.0, 0.0, 1.0)).all():
            raise ValueError(f"sides: one of -1, 0, +1 per trajectory ({n}) is needed")
        offset = states[:, 2] - states[:, 0]
        slack = 1e-12 * params.d
        inside = np.where(sides == 0.0, np.abs(offset) - model.half_gap <= slack,
                          sides * offset - model.half_gap >= -slack)
        bad = ~np.isfinite(states).all(axis=1) | ~inside
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            hg = model.half_gap
            allowed = f"[{-hg:g}, {hg:g}] m" if sides[k] == 0 else f"[{hg:g}, inf) m times the side"
            raise ValueError(f"states[{k}] = {states[k].tolist()} (side {int(sides[k])}): q - p = {float(offset[k])!r} m; "
                             f"allowed range {allowed} (the impact mass inside the gap when free, at or beyond "
                             f"the barrier it touches in contact), every value finite; {int(bad.sum())} of {n} "
                             f"starts are not")
        group = np.zeros(n, dtype=np.int64) if group is None else np.asarray(group, dtype=np.int64)
        if group.shape != (n,) or (n and (group.min() < 0 or group.max() >= len(drives))):
            raise ValueError(f"group: one index in [0, {len(drives) - 1}] per trajectory ({n}) is needed")
        self.n = n
        self.p, self.dp, self.q, self.dq = (xp.asarray(np.ascontiguousarray(states[:, j])) for j in range(4))
        self.side = xp.asarray(sides)
        if model.coupled:
            volts = np.zeros((2, n)) if volts is None else np.asarray(volts, dtype=float).reshape(2, n)
            self.volts = (xp.asarray(np.ascontiguousarray(volts[0])), xp.asarray(np.ascontiguousarray(volts[1])))
        else:
            self.volts = None  # the voltages do not act on the mechanics: not carried
        self.failed = xp.zeros((n,), dtype=xp.bool)
        self.group = group
        self._set_drives(group)
        self.step_index = 0  # hold steps taken within the present period
        self.periods = 0
        self._q_inv_t = xp.asarray(model.contact.Q_inv.T)
        self._q_t = xp.asarray(model.contact.Q.T)
        self._lam = xp.asarray(model.contact.lam)
        self._gain = xp.asarray(model.contact.gain)
        self._lam2 = xp.asarray(np.abs(model.contact.lam) ** 2)

    def _set_drives(self, group: np.ndarray) -> None:
        xp, free = self.xp, self.model.free
        tables = [drive.nodes() for drive in self.drives]
        h = np.array([drive.step for drive in self.drives])
        ec, es = free.coefficients(np, h)
        decay = np.exp(-h / self.model.tau_e)
        self._shared = len(self.drives) == 1
        if self._shared:
            (y, v), = tables
            self._node_y, self._node_v = [float(x) for x in y], [float(x) for x in v]
            self._h, self._ec, self._es, self._decay = float(h[0]), float(ec[0]), float(es[0]), float(decay[0])
        else:
            g = xp.asarray(group)
            self._node_y = [xp.take(xp.asarray(np.array([t[0][k] for t in tables])), g) for k in range(self.samples + 1)]
            self._node_v = [xp.take(xp.asarray(np.array([t[1][k] for t in tables])), g) for k in range(self.samples)]
            self._h, self._ec, self._es, self._decay = (xp.take(xp.asarray(a), g) for a in (h, ec, es, decay))

    # ------------------------------------------------------------------ reading
    @property
    def states(self) -> np.ndarray:
        """``(p, p', q, q')`` of every trajectory now, (n, 4), on the host."""
        return np.stack([to_numpy(a) for a in (self.p, self.dp, self.q, self.dq)], axis=1)

    def select(self, mask) -> "Ensemble":
        """A new ensemble of the trajectories in ``mask`` (bool, (n,), host), in their present state
        (phase and voltages included), at the start of a period."""
        mask = np.asarray(mask, dtype=bool)
        volts = None if self.volts is None else np.stack([to_numpy(v) for v in self.volts])[:, mask]
        chosen = Ensemble(self.params, self.drives, self.states[mask], self.group[mask], self.sides[mask], volts,
                          self.device, self.model)
        chosen.periods = self.periods
        return chosen

    def assign(self, which, states, sides, volts=None) -> None:
        """Put the trajectories in ``which`` (bool, (n,), host) into ``states`` ((count, 4)) on
        ``sides`` (and, under ``voltage_model = 2``, ``volts`` (2, count)), unchecked: for a
        companion a rounding's distance from a checked trajectory."""
        xp = self.xp
        which = xp.asarray(np.asarray(which, dtype=bool))
        states = np.asarray(states, dtype=float)
        for array, column in zip((self.p, self.dp, self.q, self.dq), states.T):
            array[which] = xp.asarray(np.ascontiguousarray(column))
        self.side[which] = xp.asarray(np.asarray(sides, dtype=float))
        if self.volts is not None and volts is not None:
            for array, column in zip(self.volts, np.asarray(volts, dtype=float)):
                array[which] = xp.asarray(np.ascontiguousarray(column))

    @property
    def voltages(self) -> np.ndarray | None:
        """Under ``voltage_model = 2``, the patch voltages (V) now, (2, n): left, right; else None."""
        return None if self.volts is None else np.stack([to_numpy(v) for v in self.volts])

    @property
    def sides(self) -> np.ndarray:
        """The phase of every trajectory now: 0 free, +1 or -1 in contact with that barrier."""
        return to_numpy(self.side).astype(np.int64)

    # ------------------------------------------------------------------ marching
    def advance(self, periods: int, observe: bool = False) -> dict:
        """March every trajectory ``periods`` forcing periods.

        Returns a dict of host arrays: ``sections`` (periods, n, 4), the state at the end of each
        period; ``sides`` (periods, n); ``impacts`` (periods, n), the contact onsets within each
        period; with ``observe``, ``top`` and ``bottom`` (periods, n), the largest and smallest
        ``p`` (m) of each period, from the cubic Hermite interpolant of the samples at the hold
        nodes (the harness's measure). Trajectories whose events could not be located (never seen)
        are set aside as NaN and flagged in :attr:`failed`.
        """
        if isinstance(periods, bool) or int(periods) != periods or periods < 1:
            raise ValueError(f"periods = {periods!r} is out of range; allowed range [1, inf) (whole numbers)")
        xp = self.xp
        out = {"sections": [], "sides": [], "impacts": []}
        if observe:
            out.update(top=[], bottom=[])
        for _ in range(int(periods)):
            impacts = xp.zeros((self.n,), dtype=xp.int64)
            top = bottom = self.p if observe else None
            for k in range(self.samples):
                p0, dp0 = self.p, self.dp
                impacts = impacts + self._step(k)
                if observe:
                    high, low = hermite_extremes(xp, p0, dp0, self.p, self.dp, self._h)
                    top, bottom = xp.maximum(top, high), xp.minimum(bottom, low)
            self.periods += 1
            out["sections"].append(self.states)
            out["sides"].append(self.sides)
            out["impacts"].append(to_numpy(impacts))
            if observe:
                out["top"].append(to_numpy(top))
                out["bottom"].append(to_numpy(bottom))
        return {name: np.stack(values) for name, values in out.items()}

    def _step(self, k: int):
        """One hold step for all; returns the contact onsets of each trajectory in it."""
        xp, model = self.xp, self.model
        free = model.free
        y0, v, h = self._node_y[k], self._node_v[k], self._h
        p, dp, q, dq = self.p, self.dp, self.q, self.dq
        u, du = p - y0, dp - v
        u1, du1 = free.apply((self._ec, self._es), u, du)
        end = y0 + v * h
        p1, dp1, q1 = u1 + end, du1 + v, q + dq * h
        bound = free.bound_rate * xp.sqrt(du * du + free.w2 * u * u)
        reach = xp.maximum(xp.abs(q - p), xp.abs(q1 - p1)) + bound * (h * h / 8.0)
        tol = NOISE_ULPS * EPS * (xp.abs(u) + xp.abs(q - y0) + model.half_gap)
        margin = 2.0 * xp.maximum(tol, ZERO * 2.0 * model.half_gap)
        event = (self.side != 0.0) | (reach >= model.half_gap - margin)
        safe = ~event
        self.p, self.dp, self.q = xp.where(safe, p1, p), xp.where(safe, dp1, dp), xp.where(safe, q1, q)
        if self.volts is not None:
            self.volts = tuple(xp.where(safe, volt * self._decay, volt) for volt in self.volts)
        impacts = xp.zeros((self.n,), dtype=xp.int64)
        if bool(xp.any(event)):
            impacts[event] = self._events(event, y0, v, h)
        return impacts

    def _events(self, mask, y0, v, h):
        """The trajectories in ``mask`` through their events to the end of the step; returns their
        contact onsets."""
        return event_rounds(self, mask, y0, v, h)


def hermite_extremes(xp, p0, v0, p1, v1, h):
    """The largest and smallest value of the cubic Hermite interpolant between ``(p0, v0)`` and
    ``(p1, v1)`` over a step ``h`` (s), ends included (``piezo_fmu_harness.periodic.drive``)."""
    m0, m1 = h * v0, h * v1
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = 6.0 * (p1 - p0) - 4.0 * m0 - 2.0 * m1
    c = m0
    disc = xp.sqrt(xp.maximum(b * b - 4.0 * a * c, 0.0))
    quadratic = xp.abs(a) > 1e-300
    safe_a = xp.where(quadratic, 2.0 * a, 1.0)
    safe_b = xp.where(b == 0.0, 1.0, b)
    high, low = xp.maximum(p0, p1), xp.minimum(p0, p1)
    for root in ((-b + disc) / safe_a, (-b - disc) / safe_a):
        s = xp.where(quadratic, root, -c / safe_b)
        inside = (s > 0.0) & (s < 1.0) & ~(~quadratic & (b == 0.0))
        s = xp.where(inside, s, 0.0)
        value = ((2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0
                 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1)
        high = xp.where(inside, xp.maximum(high, value), high)
        low = xp.where(inside, xp.minimum(low, value), low)
    return high, low
