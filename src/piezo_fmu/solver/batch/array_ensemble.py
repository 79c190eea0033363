"""The array engine: many trajectories marched together with array operations (issue 27), now the
test oracle of the compiled kernel (:mod:`.kernel`, issue 32), which the studies use.

An :class:`ArrayEnsemble` holds the state of ``n`` trajectories (``p, p', q, q'``, the phase, and
the patch voltages under ``voltage_model = 2``) as arrays of the array API standard (numpy, or the
standard's strict reference library, ``array-api-strict``, or CuPy), each under its own harmonic
base (:class:`~.drive.HarmonicHold`, all with the same nodes a period). A hold step is taken for all
of them at once:

1. **Free flight with no contact possible.** The closed form of free flight (:mod:`.phases`)
   takes every free trajectory to the end of the step. The impact mass's distance from the
   barriers is at most its larger value at the two ends plus ``B h^2 / 8`` in between (``B`` the
   bound on its curvature): a trajectory that stays clear of both barriers by that margin is done.
2. **The others** (in contact, or near a barrier) go through events one at a time: the next switch
   is located on the closed form (:mod:`.events`), the state is moved there, the momentum-exact
   switch rule applied (docs/model.md section 3), and so on to the end of the step. No Python loop
   runs over trajectories: each round works on the arrays of those still inside the step.

It is the same physics as the kernel, written a second way (arrays and masks, rounds over the
trajectories still inside a step, numpy's transcendental functions and pairwise sums): the tests
hold the two to each other. It is fast only in large batches, which is why the studies march on
the kernel.
"""

from __future__ import annotations

import numpy as np

from ...model.parameters import Parameters
from .events import EPS, NOISE_ULPS, ZERO
from .namespace import namespace, to_numpy
from .phases import BatchModel
from .ensemble import checked, hermite_extremes, whole
from .rounds import event_rounds


class ArrayEnsemble:
    """``n`` trajectories of the damper ``params`` under harmonic base motion (see the module's text),
    with the arguments and the methods of :class:`~.ensemble.Ensemble` but ``device``: "cpu" (numpy),
    "gpu" (CuPy) or "array-api-strict" (:func:`~.namespace.namespace`).
    """

    def __init__(self, params: Parameters, drives, states, group=None, sides=None, volts=None, device: str = "cpu",
                 model: BatchModel | None = None):
        self.xp = xp = namespace(device)
        self.device = device
        self.model = model = model or BatchModel.of(params)
        self.params = params
        drives, states, group, sides, volts = checked(params, model, drives, states, group, sides, volts)
        self.drives, self.samples = drives, drives[0].samples
        n = states.shape[0]
        self.n = n
        self.p, self.dp, self.q, self.dq = (xp.asarray(np.ascontiguousarray(states[:, j])) for j in range(4))
        self.side = xp.asarray(sides)
        if model.coupled:
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

    def select(self, mask) -> "ArrayEnsemble":
        """A new ensemble of the trajectories in ``mask`` (bool, (n,), host), in their present state
        (phase and voltages included), at the start of a period."""
        mask = np.asarray(mask, dtype=bool)
        volts = None if self.volts is None else np.stack([to_numpy(v) for v in self.volts])[:, mask]
        chosen = ArrayEnsemble(self.params, self.drives, self.states[mask], self.group[mask], self.sides[mask], volts,
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
        """March every trajectory ``periods`` forcing periods: the arrays of
        :meth:`.ensemble.Ensemble.advance`."""
        periods = whole(periods)
        xp = self.xp
        out = {"sections": [], "sides": [], "impacts": []}
        if observe:
            out.update(top=[], bottom=[])
        for _ in range(periods):
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

