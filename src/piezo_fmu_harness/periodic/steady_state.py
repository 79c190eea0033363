"""The steady state of the FMU under harmonic base motion at one frequency: a stable periodic
orbit, found by shooting and checked for stability, or a motion that is not periodic (the drive,
the section state and the measures are in :mod:`piezo_fmu_harness.periodic.drive`, the Floquet multipliers
in :mod:`piezo_fmu_harness.periodic.stability`).

**Orbits.** Time-marching at ``zeta = 0.0016`` takes minutes of simulated time, so a periodic orbit
is found by shooting: Newton on ``P^n(x) - x`` (``n`` the order of the orbit: 1, or a multiple
period detected from the marched sections) with finite-difference Jacobians, solved by least
squares (the impact mass's free drift is a neutral direction when it makes no impact) and with a
backtracking line search. A vibro-impact map is only piecewise smooth, so Newton alternates with
blocks of time-marching. An orbit counts only after a verification run: from ``x`` the section
returns within the tolerance after ``n``, ``2n`` and ``3n`` periods. Marching alone may also
settle (the sections' geometric tail within the tolerance), and is verified the same way.
Distances between states are the largest of ``|dp|, |dp'|/w, |dq|, |dq'|/w`` (m); the tolerance
is relative to ``Y``.

**Only a stable orbit is the response.** Newton converges to unstable fixed points as readily as
to stable ones, and a run started exactly on an orbit stays on it for several periods whatever its
stability. So every verified orbit gets its Floquet multipliers, and only a ``stable`` one is
reported as the steady state. An unstable orbit is kept (``unstable_orbits`` of the record) and
the search goes on from it: the drive is started on the orbit displaced along its unstable
eigenvector by ``ESCAPE_STEP`` of its size, on one side and then the other, and marching and
Newton look again for a stable orbit of order 1 to ``max_order`` (an orbit already known is not
examined twice). Each side gets half of the cycles left.

**Only an orbit the trajectory goes to.** Newton from a marched state converges to any stable
orbit near it, one the trajectory may never reach (the orbit without impacts is a neutral family,
and least squares along the free impact mass's drift land on it from a motion that still
impacts). So a stable orbit Newton finds is reported only once the march from Newton's start is
shown to be attracted to it (:mod:`piezo_fmu_harness.periodic.attraction`: the orbit's impacts in
every marched period, the distance to it shrinking as its multipliers say); otherwise it is
remembered as rejected, and marching goes on. An orbit found by marching alone is the
trajectory's own and needs no such check.

**Undecided.** When the cap on simulated cycles is reached with no stable orbit, the motion is
reported as undecided (the cap is a budget, not a verdict; one trajectory cannot show
that a motion persists, and at 0.85 ``w_n`` a sweep down reaches its orbit only at about period
340-450), with measures over a window of ``window_cycles`` forcing periods marched on from where the
search stood: the amplitude envelope (the smallest and largest half peak-to-peak of one period), the
mean power and the impacts per cycle; no single orbit's numbers. Its largest Lyapunov exponent and
modulation are measured over ``classify_cycles`` more; ``motion`` is "undecided (converging)" when
the exponent says the motion still contracts (:data:`~.motion.TRANSIENT`), else "undecided", and
``window_class`` keeps what the window alone would suggest (chaotic, quasi-periodic, strongly
modulated, transient), never a verdict: whether a motion is chaotic is for the studies of many
starts, where its persistence can be shown (``piezo-fmu fractions``, ``basins``, ``bifurcation``).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .attraction import Attractions
from .drive import HarmonicDrive, measure
from .motion import classify, undecided
from .settings import Settings
from ..fmu import FmuRunError
from .stability import Floquet, Orbit, floquet


class Shooting:
    """Finding periodic orbits at one frequency: the period map, Newton on ``P^n(x) - x``, the
    returns of marched sections and the section's phase (see the module's text)."""

    def __init__(self, drive: HarmonicDrive, settings: Settings):
        self.drive, self.settings = drive, settings
        self.tolerance = settings.tolerance * drive.amplitude
        self.newton_iterations_used = 0
        self.limit = settings.max_cycles  # the cycle count the current search may reach
        self.unstable: list[Orbit] = []
        self.stability_cycles = 0  # cycles spent on the multipliers
        self.escape_cycles = 0  # cycles spent searching on from unstable orbits
        self.attractions = Attractions(drive, self.tolerance)  # Newton's orbits against the march

    def _budget_left(self, periods: int) -> bool:
        return self.drive.cycles + periods <= self.limit

    def period_map(self, x, phase: float, order: int, capped: bool = True) -> Optional[np.ndarray]:
        """``P^order(x)``, or ``None`` if the FMU rejects the start ``x`` (outside the gap) or,
        when ``capped``, the cap on cycles would be passed."""
        if capped and not self._budget_left(order):
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
            if ratio < 1.0 and last * ratio / (1.0 - ratio) + last <= self.tolerance:
                return order
        return None


# -- the steady state of one frequency -------------------------------------------------------------

class SteadyState(Shooting):
    """Finds, verifies, checks and measures the steady state at one frequency (see the module's
    text)."""

    def solve(self, x, phase: float) -> dict:
        """The steady state from the guess ``x`` at section phase ``phase``: a JSON-safe record
        with ``settled`` (a stable orbit was found), ``method``, ``order``, the measures, the
        multipliers, the unstable orbits met, the cycles simulated and the final ``state`` and
        ``phase`` (the next frequency's guess)."""
        self._start_marching(np.asarray(x, float), phase)
        found = self._search(self._choose_section())
        escaped, begin = 0, self.drive.cycles
        while found is None and escaped < min(len(self.unstable), self.settings.MAX_ESCAPES):
            found = self._escape(self.unstable[escaped])
            escaped += 1
        self.escape_cycles = self.drive.cycles - begin
        if found is not None:
            return self._settled(found)
        return self._not_periodic()

    def _search(self, history: list) -> Optional[Orbit]:
        """March from the drive's state (``history``: the sections so far, the drive at the last)
        with Newton attempts between blocks, until a stable orbit is verified and the march shown
        to go there (returned), a new unstable one is verified (kept; ``None``), or the cycles up
        to ``self.limit`` are spent (``None``)."""
        drive, settings = self.drive, self.settings
        verify = settings.VERIFY_ORBITS
        attempts, begin = 0, drive.cycles
        while True:
            x, phase = history[-1], drive.phase
            due = drive.cycles - begin >= settings.march_cycles * (2 ** attempts - 1)
            if (settings.newton_iterations > 0 and attempts < settings.NEWTON_ATTEMPTS and due
                    and drive.clearance(x) > 0):
                attempts += 1
                saved, ahead = drive.save(), None
                try:
                    for order in self._orders(history):
                        candidate, converged = self.newton(x, phase, order)
                        orbit = self._newton_orbit(candidate, phase, order) if converged else None
                        if orbit is not None and not orbit.floquet.stable:
                            return None
                        if orbit is not None:  # stable: reported only if the march from x goes there
                            verdict = self.attractions.check(orbit, saved, self.limit)
                            if verdict.attracted:
                                return orbit
                            if ahead is None:  # marching goes on from where that march ended
                                ahead = drive.save(), verdict.sections
                    drive.restore(ahead[0] if ahead else saved)
                    history += ahead[1] if ahead else []
                finally:
                    drive.release(saved)
                    if ahead:
                        drive.release(ahead[0])
                x = history[-1]
            order = self._marched_order(history)
            if order is not None and self._budget_left(verify * order):
                # Verified by marching on: the next orbits must return within the tolerance.
                sections = drive.advance(verify * order)
                period, error = self.returns(x, sections, order)
                if period is not None and not self._known(x, phase):
                    orbit = self._examine(x, phase, period, sections, error, "marching")
                    return orbit if orbit.floquet.stable else None
                history += sections
                continue
            block = min(settings.march_cycles, self.limit - drive.cycles)
            if block <= 0:
                return None
            watched = self.attractions.watch(self.limit)  # the block, as a check of the orbits rejected
            if watched is not None and watched[0] is not None:
                return watched[0]
            history += watched[1] if watched is not None else drive.advance(block)

    def _newton_orbit(self, candidate, phase: float, order: int) -> Optional[Orbit]:
        """The orbit through Newton's converged ``candidate``: one rejected before (not verified
        again), or a new one verified and examined; ``None`` if it is a known unstable orbit, the
        cap on cycles is near, or it does not return."""
        orbit = self.attractions.known(candidate, phase)
        if orbit is not None or self._known(candidate, phase) or not self._budget_left(self.settings.VERIFY_ORBITS * order):
            return orbit
        self.drive.start(candidate, phase)
        sections = self.drive.advance(self.settings.VERIFY_ORBITS * order)
        period, error = self.returns(candidate, sections, order)
        return None if period is None else self._examine(candidate, phase, period, sections, error, "newton")

    def _examine(self, x, phase: float, period: int, sections: list, error: float, method: str) -> Orbit:
        """Measure the verified orbit through ``x`` (the drive stands at one of its sections) and
        compute its multipliers. An orbit that is not stable is kept in ``self.unstable``.

        The FMU starts only with the impact mass inside the gap, so when it is in contact at ``x``
        (chatter) the multipliers are computed at the phase of the orbit where it is farthest from
        the barriers: they do not depend on the section."""
        drive = self.drive
        measures = measure(drive, 2 * period)
        views = [(phase, [np.asarray(v) for v in sections[:period]])]
        at, at_phase = np.array(x, float), phase
        if drive.clearance(at) <= 0:
            record: list = []
            drive.advance(period, record=record)
            k = int(np.argmax([drive.clearance(state) for state in record]))
            step = (k + 1) % drive.samples
            at, at_phase = np.array(record[k]), (phase + 2.0 * math.pi * step / drive.samples) % (2.0 * math.pi)
            views.append((at_phase, [np.array(record[(k + j * drive.samples) % len(record)]) for j in range(period)]))
        result, begin = None, drive.cycles
        if drive.clearance(at) > 0:
            size = max(drive.amplitude, float(np.max(np.abs(at * drive.scale))))
            result = floquet(lambda z: self.period_map(z, at_phase, period, capped=False), at, drive.scale, size,
                             neutral=measures["impacts_per_cycle"] == 0)
        self.stability_cycles += drive.cycles - begin
        orbit = Orbit(np.array(x, float), phase, period, views, error, method, result or Floquet.unchecked(),
                      (at, at_phase), measures)
        if not orbit.floquet.stable:
            self.unstable.append(orbit)
        return orbit

    def _known(self, x, phase: float) -> bool:
        """``x`` lies on an orbit met before that is not stable (seen at the same section phase)."""
        return any(seen == phase and min(self.drive.distance(x, s) for s in states) <= 10 * self.tolerance
                   for orbit in self.unstable for seen, states in orbit.sections)

    def _escape(self, orbit: Orbit) -> Optional[Orbit]:
        """Search on from ``orbit`` displaced along its unstable eigenvector, on one side and then
        the other; each side may spend half of the cycles left."""
        drive = self.drive
        state, phase = orbit.checked_at
        if not np.any(orbit.floquet.vector):
            return None  # its multipliers could not be computed: no direction to leave it by
        size = max(drive.amplitude, float(np.max(np.abs(state * drive.scale))))
        vector = orbit.floquet.vector / float(np.max(np.abs(orbit.floquet.vector * drive.scale)))
        for sign in (1.0, -1.0):
            start = state + sign * self.settings.ESCAPE_STEP * size * vector
            left = self.settings.max_cycles - drive.cycles
            if left <= 0:
                break
            if drive.clearance(start) <= 0:
                continue
            self.limit = drive.cycles + (left // 2 if sign > 0 else left)
            try:
                drive.start(start, phase)
            except FmuRunError:
                continue
            found = self._search([start])
            if found is not None:
                return found
        self.limit = self.settings.max_cycles
        return None

    def _settled(self, orbit: Orbit) -> dict:
        sections = [[float(v) for v in state] for state in orbit.sections[0][1]]
        return {"settled": True, **orbit.record(), "motion": "periodic", "sections": sections,
                **self._bookkeeping(orbit.state, orbit.phase)}

    def _not_periodic(self) -> dict:
        """No stable orbit within the cap: the motion measured over a long window from where the
        search stands (the cycles of the window come on top of ``cycles``)."""
        drive = self.drive
        bookkeeping = self._bookkeeping(drive.state(), drive.phase)
        measures = measure(drive, self.settings.window_cycles)
        bookkeeping.update(state=[float(v) for v in drive.state()], phase=float(drive.phase))  # after the window
        motion = undecided(classify(drive, self.settings.classify_cycles))
        return {"settled": False, "method": "none", "order": None, "return_error": None, "verdict": "undecided",
                "stable": False, **measures, **motion, **bookkeeping}

    def _bookkeeping(self, x, phase: float) -> dict:
        """The cycles spent finding, checking and verifying the steady state (the measured ones come
        on top), the unstable orbits met, and where it stands: the next frequency's guess."""
        return {"cycles": self.drive.cycles, "newton_iterations": self.newton_iterations_used,
                "stability_cycles": self.stability_cycles, "escape_cycles": self.escape_cycles,
                "attraction_cycles": self.attractions.cycles, "rejected_orbits": self.attractions.records(),
                "unstable_orbits": [orbit.record() for orbit in self.unstable],
                "state": [float(v) for v in x], "phase": float(phase)}
