"""Whether a start's trajectory goes to the orbit Newton found from it.

**The rule.** The motion reported for a start (a sweep's next frequency, a continuation seed, a
basin cell) is the one its trajectory reaches. Newton on ``P^n(x) - x`` from a marched state
converges to whichever fixed point lies near it, reached by the trajectory or not; the search
(:mod:`piezo_fmu_harness.periodic.steady_state`) already refuses the unstable ones. A stable orbit
is accepted only once the marched state Newton started from is shown to be attracted to it: from
that state (the drive's saved one) ``ORDERS`` orbits are marched on (fewer when the cap on cycles
is near), and the orbit is accepted only if

(a) **every marched period makes the orbit's impacts**: the impact onsets of each period are the
    orbit's own sequence (one count a period over its ``n`` periods), from some period of it; and
(b) **the distance to the orbit shrinks as its multipliers say**: ``d_k``, the drive's scaled
    distance from the march to the nearest of the orbit's states at the same phase, ends within
    the tolerance, or at most ``SLACK`` times ``d_0 mu^(m/n)`` after ``m`` periods, ``mu`` the
    orbit's largest multiplier. For the orbit without impacts the neutral pair is left out: the
    resting impact mass's position ``q`` can be any (a family of orbits), so it is not in ``d_k``;
    its velocity ``q'`` keeps its value in free flight (multiplier exactly 1), so it must already be
    within the tolerance of the orbit's: a drifting impact mass never comes to rest, it reaches a
    barrier.

The periods are counted, and the distances taken, from the orbit's **quiet step**: the step of the
period where its impact mass is farthest from the barriers (on all its ``n`` periods), not from
the section. The section's phase is chosen early in the transient and an orbit may impact close to
it; counted from there, an impact of a march already close to the orbit would fall in one period
or the next by chance, and the state before or after it would be compared with the orbit's.

Otherwise the orbit is rejected and marching goes on from where this march ended (its periods are
the trajectory's own). A rejected orbit is remembered: Newton landing on it again costs only this
check, not a new verification and new multipliers, and every later block of the search's
marching is itself such a check of the rejected orbits (:meth:`Attractions.watch`), so that the
orbit is reported as soon as the trajectory is shown to go there, with no further Newton run.

**Why.** The motion without impacts is a neutral family (the free impact mass can rest anywhere)
and the main mass's transient decays with ``zeta = 0.0016``, about 100 forcing periods per e-fold.
Least squares along the impact mass's free drift landed Newton on that family from states whose
motion still impacted every period, and a stable orbit was reported that the trajectory never
goes to (the basin map at 1.2 w_n, the frequency response at 1.375 w_n up). Marching's own
convergence follows the trajectory and needs no such check.

**What the check cannot see.** ``SLACK`` allows for the distance's own swing: the drive's distance
is a largest component, so a decaying oscillation about the orbit (the main mass's transient,
sampled once a period) reads larger or smaller by a factor up to ``sqrt(1 + r^2)``,
``r = max(w/w_n, w_n/w)``, from one period to the next: 2.2 at the default band's ends, 0.5 and
2 w_n (the orbits the default frequency response accepts end at most 2.6 times the prediction
from their first distance). For an orbit whose largest multiplier is close to 1, (b) is
therefore weak over ``ORDERS`` orbits, and (a) and the impact mass's velocity carry the
decision. An impact that the transient makes only after the marched
orbits (a beat longer than they are) is not seen either. And a trajectory whose transient
outlasts the cap on cycles is reported as not periodic (classified, often a ``transient``), even
where Newton had already found the orbit it reaches later.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .drive import HarmonicDrive
from .stability import Orbit

#: Orbits marched from Newton's start to show that it is attracted to the orbit.
ORDERS = 8
#: How much larger than ``d_0 mu^(m/n)`` the final distance may be (the distance's own swing).
SLACK = 3.0


@dataclass(frozen=True)
class Attraction:
    """What a march showed about an orbit.

    Attributes
    ----------
    attracted : bool
        The orbit is the one the trajectory goes to (the rule holds).
    reason : str
        Why not (``""`` when attracted): ``"impacts"``, ``"drift"``, ``"distance"`` or ``"cycles"``
        (no cycle left to march).
    impacts : tuple
        The impact onsets of each marched period, counted from the orbit's quiet step.
    distances : tuple
        ``d_0, ..., d_m`` (m), at the quiet step of each marched period.
    sections : list
        The marched sections (the drive stands at the last).
    """

    attracted: bool
    reason: str
    impacts: tuple
    distances: tuple
    sections: list

    def record(self, orbit: Orbit) -> dict:
        """JSON-safe: the rejected orbit and why."""
        return {"order": orbit.order, "impacts_per_cycle": orbit.measures.get("impacts_per_cycle"),
                "amplitude": orbit.measures.get("amplitude"), "max_multiplier": orbit.floquet.largest,
                "reason": self.reason, "marched_impacts": list(self.impacts),
                "distances": [float(d) for d in self.distances]}


@dataclass(frozen=True)
class Reference:
    """An orbit as the rule sees it: its quiet step, and its impacts and states from there."""

    quiet: int        # the step of a period where the orbit's impact mass is farthest from the barriers
    sequence: tuple   # the impact onsets in each of its n periods, counted from the quiet step
    states: list      # its states at the quiet step of each of its n periods


def march(drive: HarmonicDrive, periods: int) -> tuple[list, list, list]:
    """March ``periods`` periods from where the drive stands: the state and the ``impact_count``
    after every step (the start first), and the sections."""
    states, counts = [drive.state()], [drive.totals()[0]]
    sections = drive.advance(periods, record=states, counts=counts)
    return states, counts, sections


def reference(drive: HarmonicDrive, orbit: Orbit) -> Reference:
    """March two turns of the orbit from its state at its section and read its :class:`Reference`;
    the quiet step is the one whose least clearance over the orbit's periods is the largest."""
    n, samples = orbit.order, drive.samples
    drive.start(orbit.state, orbit.phase)
    states, counts, _ = march(drive, 2 * n)
    clearance = [min(drive.clearance(states[j + k * samples]) for k in range(n)) for j in range(samples)]
    quiet = int(np.argmax(clearance))
    starts = [quiet + k * samples for k in range(n)]
    return Reference(quiet, tuple(counts[j + samples] - counts[j] for j in starts), [np.asarray(states[j]) for j in starts])


def nearest(drive: HarmonicDrive, orbit: Orbit, ref: Reference, x) -> tuple[np.ndarray, float]:
    """The orbit's state at its quiet step nearest to ``x`` and the drive's scaled distance (m) to
    it; the impact mass's position left out for the orbit without impacts (its neutral pair)."""
    weights = drive.scale.copy()
    if orbit.floquet.neutral:
        weights[2] = 0.0
    gaps = [float(np.max(np.abs((np.asarray(x) - s) * weights))) for s in ref.states]
    k = int(np.argmin(gaps))
    return ref.states[k], gaps[k]


def follows(counts, sequence) -> bool:
    """The counts of consecutive periods are the orbit's ``sequence``, from one of its periods."""
    n = len(sequence)
    return any(all(c == sequence[(shift + k) % n] for k, c in enumerate(counts)) for shift in range(n))


def judge(drive: HarmonicDrive, orbit: Orbit, ref: Reference, marched: tuple, tolerance: float) -> Attraction:
    """The rule (see the module's text) applied to ``orbit`` over the ``marched`` periods
    (:func:`march`, from the orbit's section phase)."""
    states, counts, sections = marched
    samples = drive.samples
    points = range(ref.quiet, len(states), samples)  # the quiet step of each marched period
    impacts = [counts[j + samples] - counts[j] for j in points if j + samples < len(states)]
    distances = [nearest(drive, orbit, ref, states[j])[1] for j in points]
    last = states[points[-1]]
    predicted = SLACK * distances[0] * orbit.floquet.largest ** ((len(distances) - 1) / orbit.order)
    reason = ""
    if len(impacts) < orbit.order:
        reason = "cycles"
    elif not follows(impacts, ref.sequence):
        reason = "impacts"
    elif orbit.floquet.neutral and abs(last[3] - nearest(drive, orbit, ref, last)[0][3]) * drive.scale[3] > tolerance:
        reason = "drift"
    elif distances[-1] > max(tolerance, predicted):
        reason = "distance"
    return Attraction(not reason, reason, tuple(impacts), tuple(distances), sections)


def window(order: int, cycles_left: int) -> Optional[int]:
    """The periods to march: ``ORDERS`` orbits and the period that completes the last one counted
    from the quiet step, or the whole orbits the cap on cycles leaves (``None`` when not one)."""
    orbits = min(ORDERS, (cycles_left - 1) // order)
    return orbits * order + 1 if orbits > 0 else None


class Attractions:
    """The rule over one start's search: checks the stable orbits Newton finds against the march
    from its start, remembers those rejected (with their :class:`Reference`), and watches the
    search's marching for them."""

    def __init__(self, drive: HarmonicDrive, tolerance: float):
        self.drive, self.tolerance = drive, tolerance
        self.rejected: dict[int, tuple[Orbit, Reference, Attraction]] = {}  # by id of the orbit
        self.cycles = 0  # cycles of the checks after Newton (the orbits' references and the marches)

    def known(self, x, phase: float) -> Optional[Orbit]:
        """A rejected orbit through ``x`` (seen at the same section phase), if any."""
        return next((orbit for orbit, _, _ in self.rejected.values() if orbit.phase == phase
                     and min(self.drive.distance(x, s) for s in orbit.sections[0][1]) <= 10 * self.tolerance), None)

    def check(self, orbit: Orbit, saved, limit: int) -> Attraction:
        """Apply the rule to ``orbit`` from the drive's ``saved`` state (Newton's start), marching
        while the drive's cycles stay within ``limit``; the drive stands where the march ended."""
        drive, begin = self.drive, self.drive.cycles
        seen = self.rejected.get(id(orbit))
        ref = seen[1] if seen else reference(drive, orbit)
        drive.restore(saved)
        periods = window(orbit.order, limit - drive.cycles)
        verdict = (judge(drive, orbit, ref, march(drive, periods), self.tolerance) if periods
                   else Attraction(False, "cycles", (), (), []))
        self._note(orbit, ref, verdict)
        self.cycles += drive.cycles - begin
        return verdict

    def watch(self, limit: int) -> Optional[tuple[Optional[Orbit], list]]:
        """March the search's next block as a check of the rejected orbits seen at the drive's
        section phase: ``ORDERS`` orbits of the longest (fewer near ``limit``). Returns the orbit
        the march is attracted to (or ``None``) and the marched sections; ``None`` when there is
        no such orbit to watch or no cycle left."""
        drive = self.drive
        watched = [(orbit, ref) for orbit, ref, _ in self.rejected.values() if orbit.phase == drive.phase]
        periods = window(max(orbit.order for orbit, _ in watched), limit - drive.cycles) if watched else None
        if periods is None:
            return None
        marched = march(drive, periods)
        for orbit, ref in watched:
            verdict = judge(drive, orbit, ref, marched, self.tolerance)
            self._note(orbit, ref, verdict)
            if verdict.attracted:
                return orbit, marched[2]
        return None, marched[2]

    def _note(self, orbit: Orbit, ref: Reference, verdict: Attraction) -> None:
        if verdict.attracted:
            self.rejected.pop(id(orbit), None)
        else:
            self.rejected[id(orbit)] = (orbit, ref, verdict)

    def records(self) -> list[dict]:
        """JSON-safe: the rejected orbits, each with the last check's verdict."""
        return [verdict.record(orbit) for orbit, _, verdict in self.rejected.values()]
