"""The steady state of the FMU under harmonic base motion at one frequency: shooting and
verification (the drive, the section state and the measures of an orbit are in
:mod:`piezo_fmu_harness.drive`).

**Steady state.** Time-marching at ``zeta = 0.0016`` takes minutes of simulated time, so the
periodic orbit is found by shooting: Newton on ``P^n(x) - x`` (``n`` the order of the orbit:
1, or a multiple period detected from the marched sections) with finite-difference Jacobians,
solved by least squares (the impact mass's free drift is a neutral direction when it makes no
impact) and with a backtracking line search. A vibro-impact map is only piecewise smooth, so
Newton alternates with blocks of time-marching. An orbit is accepted only after a verification
run: from ``x`` the section returns within the tolerance after ``n``, ``2n`` and ``3n`` periods.
Marching alone may also settle (the sections' geometric tail within the tolerance), and is
verified the same way. When the cap on simulated cycles is reached first, the point is reported
as not settled, with measures from its last periods. Distances between states are the largest
of ``|dp|, |dp'|/w, |dq|, |dq'|/w`` (m); the tolerance is relative to ``Y``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .drive import HarmonicDrive, measure
from .fmu import FmuRunError


@dataclass(frozen=True)
class Settings:
    """How one frequency's steady state is found and checked.

    Attributes
    ----------
    samples : int
        Communication steps per forcing period (the base's nodes), >= 16.
    tolerance : float
        Steady-state tolerance on the section's return, relative to the base amplitude ``Y``.
    max_cycles : int
        Cap on the forcing cycles simulated for one frequency (Newton's evaluations included).
    newton_iterations : int
        Newton iterations per attempt; 0 finds the steady state by time-marching alone.
    max_order : int
        Longest period of an orbit looked for, in forcing periods.
    warmup_cycles : int
        Forcing cycles marched from the guess before the first Newton attempt (the last one
        chooses the section's phase).
    march_cycles : int
        Forcing cycles marched between Newton attempts.
    """

    samples: int = 64
    tolerance: float = 1e-6
    max_cycles: int = 400
    newton_iterations: int = 12
    max_order: int = 4
    warmup_cycles: int = 2
    march_cycles: int = 8

    #: Newton attempts per frequency (each after a block of marching).
    NEWTON_ATTEMPTS = 3
    #: Finite-difference step of the Jacobian, relative to the state's scale.
    FD_STEP = 1e-7
    #: Returns the verification run checks, in orbits.
    VERIFY_ORBITS = 3


# -- the steady state of one frequency -------------------------------------------------------------

class SteadyState:
    """Finds, verifies and measures the steady state at one frequency (see the module's text)."""

    def __init__(self, drive: HarmonicDrive, settings: Settings):
        self.drive, self.settings = drive, settings
        self.tolerance = settings.tolerance * drive.amplitude
        self.newton_iterations_used = 0

    def _budget_left(self, periods: int) -> bool:
        return self.drive.cycles + periods <= self.settings.max_cycles

    def period_map(self, x, phase: float, order: int) -> Optional[np.ndarray]:
        """``P^order(x)``, or ``None`` if the FMU rejects the start ``x`` (outside the gap) or
        the cap on cycles would be passed."""
        if not self._budget_left(order):
            return None
        try:
            self.drive.start(x, phase)
            return self.drive.advance(order)[-1]
        except FmuRunError:  # the FMU checks the initial state at its first step
            return None

    def newton(self, x, phase: float, order: int) -> tuple[np.ndarray, bool]:
        """Newton on ``P^order(x) - x``; returns the last iterate and whether its residual is
        within a tenth of the tolerance."""
        drive, s = self.drive, self.drive.scale
        fx = self.period_map(x, phase, order)
        if fx is None:
            return x, False
        residual = (fx - x) * s
        for _ in range(self.settings.newton_iterations):
            norm = float(np.max(np.abs(residual)))
            if norm <= 0.1 * self.tolerance:
                return x, True
            self.newton_iterations_used += 1
            step = self.settings.FD_STEP * max(drive.amplitude, float(np.max(np.abs(x * s))))
            jacobian = np.empty((4, 4))
            for i in range(4):
                for sign in (1.0, -1.0):  # the other side when the FMU rejects a shifted start
                    shifted = x.copy()
                    shifted[i] += sign * step / s[i]
                    fi = self.period_map(shifted, phase, order)
                    if fi is not None:
                        jacobian[:, i] = sign * ((fi - fx) * s) / step
                        break
                else:
                    return x, False
            delta = np.linalg.lstsq(jacobian - np.eye(4), -residual, rcond=1e-12)[0] / s
            for _ in range(5):  # backtracking: halve the step until the residual falls
                trial = x + delta
                ft = self.period_map(trial, phase, order)
                if ft is not None and float(np.max(np.abs((ft - trial) * s))) < norm:
                    x, fx, residual = trial, ft, (ft - trial) * s
                    break
                delta = 0.5 * delta
            else:
                return x, False
        return x, float(np.max(np.abs(residual))) <= 0.1 * self.tolerance

    def returns(self, x, sections: list, order: int) -> tuple[Optional[int], float]:
        """The least period (<= ``order``) at which ``sections`` (after ``x``) return to ``x``
        within the tolerance at every multiple, and the largest such return distance (m);
        ``(None, smallest distance)`` if none does."""
        distances = [self.drive.distance(section, x) for section in sections]
        total = len(distances)
        for period in range(1, order + 1):
            worst = max(distances[k - 1] for k in range(period, total + 1, period))
            if worst <= self.tolerance:
                return period, worst
        return None, min(distances)

    def solve(self, x, phase: float) -> dict:
        """The steady state from the guess ``x`` at section phase ``phase``: a JSON-safe record
        with ``settled``, ``method``, ``order``, the measures, the cycles simulated and the final
        ``state`` and ``phase`` (the next frequency's guess)."""
        drive, settings = self.drive, self.settings
        verify = settings.VERIFY_ORBITS
        self._start_marching(np.asarray(x, float), phase)
        history = self._choose_section()
        attempts = 0
        while True:
            x, phase = history[-1], drive.phase
            if settings.newton_iterations > 0 and attempts < settings.NEWTON_ATTEMPTS and drive.clearance(x) > 0:
                attempts += 1
                saved = drive.save()
                try:
                    for order in self._orders(history):
                        candidate, converged = self.newton(x, phase, order)
                        if converged and self._budget_left(verify * order):
                            drive.start(candidate, phase)
                            period, error = self.returns(candidate, drive.advance(verify * order), order)
                            if period is not None:
                                return self._settled(candidate, phase, period, error, "newton")
                    drive.restore(saved)
                finally:
                    drive.release(saved)
            order = self._marched_order(history)
            if order is not None and self._budget_left(verify * order):
                # Verified by marching on: the next orbits must return within the tolerance.
                sections = drive.advance(verify * order)
                period, error = self.returns(x, sections, order)
                if period is not None:
                    return self._settled(x, phase, period, error, "marching")
                history += sections
                continue
            block = min(settings.march_cycles, settings.max_cycles - drive.cycles)
            if block <= 0:
                break
            history += drive.advance(block)
        return self._not_settled()

    # -- pieces of solve ---------------------------------------------------------------------------

    def _start_marching(self, x, phase: float) -> None:
        """Start the drive from ``x``; a guess with the impact mass outside the gap (a previous
        frequency's state in contact) is moved onto the nearer barrier first."""
        if self.drive.clearance(x) < 0:
            x = x.copy()
            x[2] = x[0] + math.copysign(0.5 * self.drive.gap, x[2] - x[0])
            x[3] = x[1]
        self.drive.start(x, phase)

    def _choose_section(self) -> list[np.ndarray]:
        """March the first periods, then move the section to the phase of the last period where
        the impact mass is farthest from the barriers, unless it already is at least half that
        far. Returns the sections marched at the final phase (the drive stands at the last)."""
        drive, settings = self.drive, self.settings
        history = [drive.state()]
        history += drive.advance(max(0, min(settings.warmup_cycles, settings.max_cycles) - 1))
        record: list = []
        history += drive.advance(1, record=record)
        clearances = [drive.clearance(state) for state in record]
        best = int(np.argmax(clearances))
        if clearances[-1] > 0 and clearances[-1] >= 0.5 * clearances[best]:
            return history
        phase = (drive.phase + 2.0 * math.pi * (best + 1) / drive.samples) % (2.0 * math.pi)
        state = np.array(record[best])
        drive.start(state, phase)
        return [state]

    def _orders(self, history: list) -> list[int]:
        """Orders for Newton to try: 1, then the order the marched sections suggest."""
        suggested = self._suggested_order(history)
        return [1] if suggested == 1 else [1, suggested]

    def _suggested_order(self, history: list) -> int:
        """The ``n`` <= max_order whose return ``|x_k - x_{k-n}|`` is smallest over the last sections."""
        drive, top = self.drive, self.settings.max_order
        if len(history) < top + 1:
            return 1
        gaps = [drive.distance(history[-1], history[-1 - n]) for n in range(1, top + 1)]
        best = int(np.argmin(gaps)) + 1
        return best if gaps[best - 1] < 0.1 * gaps[0] else 1

    def _marched_order(self, history: list) -> Optional[int]:
        """The order at which the marched sections have converged: their geometric tail, estimated
        from the returns over the last orbits, is within the tolerance. ``None`` if none has."""
        drive = self.drive
        for order in range(1, self.settings.max_order + 1):
            span = 4 * order
            if len(history) < span + order:
                break
            returns = [drive.distance(history[k], history[k - order])
                       for k in range(len(history) - span, len(history))]
            first, last = returns[0], returns[-1]
            if last == 0.0:
                return order
            if first <= 0.0 or last >= first:
                continue
            ratio = (last / first) ** (1.0 / (len(returns) - 1))
            if last * ratio / (1.0 - ratio) + last <= self.tolerance:
                return order
        return None

    def _settled(self, x, phase: float, period: int, error: float, method: str) -> dict:
        # The verification left the drive at a section of the orbit, more than one orbit after its
        # start: the circuit has settled; two orbits are measured.
        bookkeeping = self._bookkeeping(x, phase)
        return {"settled": True, "method": method, "order": period, "return_error": error,
                **measure(self.drive, 2 * period), **bookkeeping}

    def _not_settled(self) -> dict:
        drive = self.drive
        bookkeeping = self._bookkeeping(drive.state(), drive.phase)
        return {"settled": False, "method": "none", "order": None, "return_error": None,
                **measure(drive, 2), **bookkeeping}

    def _bookkeeping(self, x, phase: float) -> dict:
        """The cycles spent finding and verifying the steady state (the measured ones come on top)
        and where it stands: the next frequency's guess."""
        return {"cycles": self.drive.cycles, "newton_iterations": self.newton_iterations_used,
                "state": [float(v) for v in x], "phase": float(phase)}
