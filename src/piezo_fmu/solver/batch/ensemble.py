"""Many trajectories of one damper marched together, hold step by hold step, exactly, on the
compiled kernel (:mod:`.kernel`).

An :class:`Ensemble` holds the state of ``n`` trajectories (``p, p', q, q'``, the phase, and the
patch voltages under ``voltage_model = 2``), each under its own harmonic base
(:class:`~.drive.HarmonicHold`, all with the same nodes a period). :meth:`Ensemble.advance` hands a
whole block of periods to the kernel, which takes each trajectory through its hold steps: free
flight in closed form where no contact is possible in a step, else event by event (the switch
located rigorously on the closed form of the phase, the momentum-exact switch rule applied,
docs/model.md section 3) to the step's end. A trajectory's cost does not depend on how many march
with it, and it gives the same bits alone and in a batch.

The base is the FMUs' first-order hold (:mod:`.drive`), so an ensemble marches the motion an FMU
marched by the harness shows, and agrees with the scalar core (:class:`piezo_fmu.solver.Simulator`)
and the FMUs to rounding on orbits that are stable.
"""

from __future__ import annotations

import numpy as np

from ...model.parameters import Parameters
from . import kernel
from .drive import HarmonicHold
from .model import BatchModel


def checked(params: Parameters, model: BatchModel, drives, states, group, sides, volts) -> tuple:
    """The arguments of an ensemble, checked (see :class:`Ensemble`): ``(drives, states, group,
    sides, volts)`` as host arrays, ``volts`` (2, n) zeros when not given."""
    drives = [drives] if isinstance(drives, HarmonicHold) else list(drives)
    if not drives:
        raise ValueError("drives: none given; allowed: one HarmonicHold or more")
    samples = {drive.samples for drive in drives}
    if len(samples) != 1:
        raise ValueError(f"drives: samples {sorted(samples)} differ; allowed: one number of nodes a period for all")
    states, sides, volts = checked_states(params, model, states, sides, volts)
    n = states.shape[0]
    group = np.zeros(n, dtype=np.int64) if group is None else np.asarray(group, dtype=np.int64)
    if group.shape != (n,) or (n and (group.min() < 0 or group.max() >= len(drives))):
        raise ValueError(f"group: one index in [0, {len(drives) - 1}] per trajectory ({n}) is needed")
    return drives, states, group, sides, volts


def checked_states(params: Parameters, model: BatchModel, states, sides, volts) -> tuple:
    """The starts of an ensemble, checked: ``(states, sides, volts)`` as host arrays ((n, 4), (n,),
    (2, n)), ``sides`` free and ``volts`` zeros when not given; the impact mass inside the gap when
    free, at or beyond the barrier it touches in contact, every value finite."""
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
    volts = np.zeros((2, n)) if volts is None else np.asarray(volts, dtype=float).reshape(2, n)
    return states, sides, volts


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
        "cpu" (numba, every core) or "gpu" (numba's CUDA target, one thread a trajectory).
    model : BatchModel, optional
        ``BatchModel.of(params)``, when the caller has it already.
    """

    def __init__(self, params: Parameters, drives, states, group=None, sides=None, volts=None, device: str = "cpu",
                 model: BatchModel | None = None, tables=None):
        if error := kernel.device_error(device):
            raise ValueError(error)
        model = model or BatchModel.of(params)
        drives, states, group, sides, volts = checked(params, model, drives, states, group, sides, volts)
        self._fill(params, model, tables or kernel.Tables(model, drives), drives, states, group, sides, volts, device)

    @classmethod
    def checked_by_caller(cls, params: Parameters, model: BatchModel, tables, drives: list, states: np.ndarray,
                          group: np.ndarray, sides: np.ndarray) -> "Ensemble":
        """An ensemble on the CPU of ``states`` ((n, 4) floats), ``group`` ((n,) int64) and ``sides``
        ((n,) floats) that the caller has checked already, by a test at least as strict as
        :func:`checked`'s, under ``drives`` (a list), with ``model`` and ``tables`` given: the orbit
        finder's thousands of small ensembles, whose checks cost more than their marching."""
        ensemble = cls.__new__(cls)
        ensemble._fill(params, model, tables, drives, states, group, sides, np.zeros((2, len(states))), "cpu")
        return ensemble

    def _fill(self, params, model, tables, drives, states, group, sides, volts, device) -> None:
        self.device, self.model, self.params = device, model, params
        self.drives, self.samples = drives, drives[0].samples
        self.n = n = states.shape[0]
        self._tables = tables
        self._state = np.empty((7, n))
        self._state[:4], self._state[4], self._state[5:] = states.T, sides, volts
        self.failed = np.zeros(n, dtype=bool)
        self.group = group
        self.periods = 0

    # ------------------------------------------------------------------ reading
    @property
    def states(self) -> np.ndarray:
        """``(p, p', q, q')`` of every trajectory now, (n, 4)."""
        return np.ascontiguousarray(self._state[:4].T)

    @property
    def voltages(self) -> np.ndarray | None:
        """Under ``voltage_model = 2``, the patch voltages (V) now, (2, n): left, right; else None."""
        return self._state[5:].copy() if self.model.coupled else None

    @property
    def sides(self) -> np.ndarray:
        """The phase of every trajectory now: 0 free, +1 or -1 in contact with that barrier."""
        return self._state[4].astype(np.int64)

    def select(self, mask) -> "Ensemble":
        """A new ensemble of the trajectories in ``mask`` (bool, (n,)), in their present state (phase
        and voltages included), at the start of a period."""
        mask = np.asarray(mask, dtype=bool)
        chosen = Ensemble(self.params, self.drives, self.states[mask], self.group[mask], self._state[4][mask],
                          self._state[5:, mask], self.device, self.model, self._tables)
        chosen.failed = self.failed[mask]
        chosen.periods = self.periods
        return chosen

    def assign(self, which, states, sides, volts=None) -> None:
        """Put the trajectories in ``which`` (bool, (n,)) into ``states`` ((count, 4)) on ``sides``
        (and, under ``voltage_model = 2``, ``volts`` (2, count)), unchecked."""
        which = np.asarray(which, dtype=bool)
        self._state[:4, which] = np.asarray(states, dtype=float).T
        self._state[4, which] = np.asarray(sides, dtype=float)
        if self.model.coupled and volts is not None:
            self._state[5:, which] = np.asarray(volts, dtype=float)

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
        periods = whole(periods)
        out = kernel.march(self.device, self._tables, self._state, self.failed, self.group, periods, observe)
        self.periods += periods
        if not observe:
            del out["top"], out["bottom"]
        return out

    def separate(self, offset, scale, delta, periods: int) -> dict:
        """March every trajectory ``periods`` periods beside a companion ``offset`` ((n, 4)) away, in
        the same phase, brought back to the distance ``delta`` ((n,), m, distances weighted by
        ``scale`` (n, 4)) along their separation after every period: the measure of the largest
        Lyapunov exponent. Returns host arrays (periods, n): ``logs``, the log of each period's
        stretch; ``samples``, ``p`` at each section; ``impacts``; ``top`` and ``bottom``; and
        ``offset`` (n, 4), the companion's offset at the end."""
        periods = whole(periods)
        offset = np.ascontiguousarray(np.asarray(offset, dtype=float).T)
        out = kernel.separate(self.device, self._tables, self._state, self.failed, self.group, offset,
                              np.asarray(scale, dtype=float).T, np.asarray(delta, dtype=float), periods)
        self.periods += periods
        out["offset"] = offset.T.copy()
        return out


def whole(periods) -> int:
    """``periods`` checked: a whole number of periods, at least one."""
    if isinstance(periods, bool) or int(periods) != periods or periods < 1:
        raise ValueError(f"periods = {periods!r} is out of range; allowed range [1, inf) (whole numbers)")
    return int(periods)

