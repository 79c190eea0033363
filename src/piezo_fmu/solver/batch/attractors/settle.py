"""Where each start goes: many starts marched on the batch engine to the motion they reach.

**The rule.** The motion reported for a start is the one its trajectory reaches. A stable orbit
found by Newton is not enough: Newton converges to whatever orbit lies near, and a trajectory can
pass close to one stable orbit on its way to another. So the starts are marched, a
block of periods at a time, and a start is labelled only when its own trajectory shows where it
goes:

- **an orbit with impacts**: its sections, over the last blocks, come within a small distance
  (``LINEAR_REACH`` of the orbit's size) of a known stable orbit, make the orbit's contact onsets
  in every period (the same impact sequence), and their distance to it shrinks at least as fast as
  its largest multiplier predicts (``RATE_SLACK``), or is already within the tolerance. The orbits
  are found by Newton (:mod:`.orbits`) from trajectories whose returns are shrinking, verified,
  and kept only when their multipliers lie inside the unit circle; Newton only accelerates what
  marching shows: it never labels a start by itself.
- **the motion without impacts**: the trajectory is free with its impact mass at rest and provably
  never reaches a barrier again (:func:`.orbits.free_for_ever`): it ends on the family of orbits
  without impacts, whatever the slowly decaying transient (about 100 periods an e-fold at
  ``zeta = 0.0016``) still does.
- **undecided**: no label within ``max_cycles``. The cap is a budget, not a verdict:
  a start that has not been seen reaching an orbit may be on a long chaotic transient, on an orbit
  longer than ``max_order``, or on an attractor that is not periodic, and one trajectory cannot
  say which. Its largest Lyapunov exponent with a 95% interval (a companion trajectory ``1e-8``
  away, renormalised every period), the modulation of its amplitude and the line share of its
  section's spectrum are measured over ``classify_cycles`` more periods
  (:func:`.trajectories.statistics`). Whether the undecided starts of a drive **persist** (a
  chaotic or quasi-periodic attractor) is a question about all its starts, not one: their
  survival curve, fitted by the caller (``piezo_fmu_harness.starts.transients``) from the
  periods at which the others were resolved.

Everything runs on arrays of trajectories; the resolved ones leave the ensemble after each block.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..drive import HarmonicHold
from ..ensemble import Ensemble
from ..kernel import target
from ..model import BatchModel
from . import books
from .measures import empty_measures, measure
from .orbits import LinearOrbit, Orbit, OrbitFinder, linear_orbit, scale_of

#: A trajectory is taken to be on its way to an orbit within this fraction of the orbit's size.
LINEAR_REACH = 0.05
#: How much slower than its largest multiplier's modulus (per period) the distance may shrink.
RATE_SLACK = 0.02
#: Returns of a seed for Newton: within this fraction of the size, and shrinking.
SEED_REACH = 0.1
#: The labels of the starts that are on no orbit (see :class:`Settled`).
UNDECIDED, SET_ASIDE = -1, -2


@dataclass(frozen=True)
class SettleSettings:
    """How far and how the starts are marched.

    Attributes
    ----------
    tolerance : float
        Steady-state tolerance, relative to each drive's ``Y``.
    max_cycles : int
        The budget: periods a start is marched at most; one not resolved by then is undecided.
    block : int
        Periods between two looks at the trajectories.
    max_order : int
        Longest orbit looked for, in forcing periods (16: past the Neimark-Sacker point, at
        1.325 ``w_n``, the motion locks on the torus to a stable orbit of order 13).
    classify_cycles : int
        Periods over which an undecided motion is measured (its exponent's interval needs a long
        window: the batch means of ten batches).
    seeds : int
        Newton seeds tried per drive and block, at most.
    """

    tolerance: float = 1e-6
    max_cycles: int = 1000
    block: int = 20
    max_order: int = 16
    classify_cycles: int = 200
    seeds: int = 4


@dataclass
class Quiet:
    """The motion without impacts of one drive: the family of orbits where the impact mass rests."""

    group: int
    orbit: LinearOrbit


@dataclass
class Settled:
    """Where each start went (host arrays over the starts).

    ``labels``: index into ``attractors`` (an :class:`~.orbits.Orbit` or a :class:`Quiet`),
    :data:`UNDECIDED` (-1) for a start the budget did not resolve, :data:`SET_ASIDE` (-2) for a
    trajectory the engine set aside (whether undecided starts persist, chaotic or quasi-periodic, is
    the caller's to judge from all the starts of a drive; the harness's records then say so by their
    ``kind``); ``periods``: periods marched when the
    label was given (``max_cycles`` for the others: the budget); for the undecided starts:
    ``exponent`` with ``exponent_low``/``exponent_high`` (1/period, 95%), ``modulation``,
    ``impacts_per_cycle``, ``amplitude``, ``amplitude_min``, ``amplitude_max`` (m) and
    ``line_share``, NaN elsewhere, and ``samples``, ``p`` (m) at each section of the window they
    were measured over; ``unstable``: orbits Newton found that are not stable (never a label);
    ``cycles``: start-periods marched in all; ``final`` and ``final_sides``: where each trajectory
    goes, at the section: the point of its orbit it was nearest when it got its label, the motion
    without impacts with its impact mass where it rests, for an undecided start its state after the
    measuring window, and for one set aside its start: where a sweep's next frequency starts.
    """

    labels: np.ndarray
    periods: np.ndarray
    attractors: list
    unstable: list
    measures: dict
    cycles: int = 0
    final: np.ndarray = None
    final_sides: np.ndarray = None
    samples: np.ndarray = None

    def records(self) -> tuple[list[dict], list[dict]]:
        """JSON-safe: one record per start (``label``, ``periods`` and, for an undecided start, its
        measures) and one per attractor (:func:`describe`)."""
        starts = []
        for j, label in enumerate(self.labels.tolist()):
            record = {"label": int(label), "periods": int(self.periods[j])}
            if label == UNDECIDED:
                record.update({name: _finite(values[j]) for name, values in self.measures.items()})
            starts.append(record)
        return starts, [describe(a) for a in self.attractors]


def describe(attractor) -> dict:
    """A JSON-safe description of an attractor of :func:`settle` (SI): ``kind`` ("orbit" or "no
    impacts"), its drive's ``group``, the amplitude (m) as the harness measures it, and for an
    orbit its order, contact onsets per period, section states and sides, and multipliers."""
    if isinstance(attractor, Quiet):
        orbit = attractor.orbit
        return {"kind": "no impacts", "group": attractor.group, "order": 1, "impacts": [0],
                "impacts_per_cycle": 0.0, "amplitude": orbit.amplitude, "top": orbit.top, "bottom": orbit.bottom,
                "sections": [[float(v) for v in orbit.nodes[0]] + [None, 0.0]], "sides": [0],
                "max_multiplier": orbit.multiplier, "multipliers": [], "multiplier_error": 0.0}
    return {"kind": "orbit", "group": attractor.group, "order": attractor.order, "impacts": list(attractor.impacts),
            "impacts_per_cycle": attractor.impacts_per_cycle, "amplitude": attractor.amplitude,
            "top": attractor.top, "bottom": attractor.bottom,
            "sections": [[float(v) for v in row] for row in attractor.sections],
            "sides": [int(s) for s in attractor.sides], "max_multiplier": attractor.largest,
            "multipliers": [[mu.real, mu.imag] for mu in attractor.multipliers],
            "multiplier_error": attractor.error}


def _finite(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def settle(params, drives, starts, groups=None, settings: SettleSettings = SettleSettings(),
           device: str = "cpu", progress=None, sides=None, measured: bool = True) -> Settled:
    """March ``starts`` ((n, 4): ``p, p', q, q'``, free unless ``sides`` says otherwise) under
    ``drives`` (one, or one per group) to where each goes (see the module's text), on ``device``;
    the orbit finder's small ensembles march on the CPU. ``progress(done, total)`` is called after
    each block. With ``measured`` False, the starts undecided at the budget are not measured (a
    cloud wanted only for when its starts resolve): they come back with NaN measures, no samples,
    and their start as ``final``."""
    drives = [drives] if isinstance(drives, HarmonicHold) else list(drives)
    starts = np.asarray(starts, float)
    n = len(starts)
    groups = np.zeros(n, int) if groups is None else np.asarray(groups, int)
    model = BatchModel.of(params)
    tolerance = np.array([settings.tolerance * max(d.amplitude, 1e-300) for d in drives])
    finder = OrbitFinder(model, drives, tolerance)  # on the CPU whatever ``device`` (its small ensembles)
    linear = [linear_orbit(model, d) for d in drives]
    scales = np.array([scale_of(d) for d in drives])
    state = _State(n, settings)
    quiet: dict[int, int] = {}
    sides = np.zeros(n) if sides is None else np.asarray(sides, float)
    ens = Ensemble(params, drives, starts, groups, sides, device=device, model=model, tables=finder.tables)
    final, final_sides = starts.copy(), sides.copy()
    ids = np.arange(n)
    # A start may already be free for ever.
    _label_quiet(state, model, linear, quiet, ids, groups, starts, sides, 0)
    _destinations(state, final, final_sides, ids[state.labels >= 0], starts[state.labels >= 0], scales)
    keep = state.labels[ids] == -1
    ens, ids = (ens.select(keep), ids[keep]) if not keep.all() else (ens, ids)
    history = None
    marched = 0
    while len(ids) and marched < settings.max_cycles:
        periods = min(settings.block, settings.max_cycles - marched)
        record = ens.advance(periods)
        finder.cycles += periods * len(ids)
        marched += periods
        history = _extend(history, record, 2 * settings.block + settings.max_order)
        g = groups[ids]
        failed = ens.failed.astype(bool)
        state.labels[ids[failed]] = -2
        state.periods[ids[failed]] = marched
        _label_quiet(state, model, linear, quiet, ids, g, record["sections"][-1], record["sides"][-1], marched)
        _find_orbits(state, finder, history, ids, g, scales, settings)
        _label_orbits(state, history, ids, g, scales, tolerance, marched)
        keep = state.labels[ids] == -1
        if not keep.all():
            _destinations(state, final, final_sides, ids[~keep], record["sections"][-1][~keep], scales)
            ens, ids = ens.select(keep), ids[keep]
            history = {name: values[:, keep] for name, values in history.items()}
        if progress is not None:
            progress(n - len(ids), n)
    state.periods[ids] = marched
    samples = np.full((n, settings.classify_cycles), np.nan)
    measures = empty_measures(n)
    if measured and len(ids):
        final[ids], final_sides[ids], samples[ids] = measure(ens, ids, measures, scales, settings.classify_cycles, finder)
    return Settled(state.labels, state.periods, state.attractors, state.unstable, measures, finder.cycles, final,
                   final_sides, samples)


class _State:
    def __init__(self, n: int, settings: SettleSettings):
        self.labels = np.full(n, -1)
        self.periods = np.zeros(n, dtype=np.int64)
        self.attractors: list = []
        self.unstable: list = []
        self.settings = settings


def _destinations(state, final, final_sides, chosen, sections, scales) -> None:
    """Where the labelled trajectories ``chosen`` (now at ``sections``) go (see :class:`Settled`); one
    set aside keeps its start."""
    for j, x in zip(chosen, sections):
        if state.labels[j] == SET_ASIDE:
            continue
        attractor = state.attractors[state.labels[j]]
        if isinstance(attractor, Quiet):
            final[j] = [*attractor.orbit.nodes[0], x[2], 0.0]
            final_sides[j] = 0.0
        else:
            scale = scales[attractor.group]
            k = int(np.abs((attractor.sections - x) * scale).max(axis=1).argmin())
            final[j], final_sides[j] = attractor.sections[k], attractor.sides[k]


def _extend(history, record, keep: int) -> dict:
    fresh = {name: record[name] for name in ("sections", "sides", "impacts")}
    if history is None:
        return fresh
    return {name: np.concatenate([history[name], fresh[name]])[-keep:] for name in fresh}


def _label_quiet(state, model, linear, quiet, ids, groups, sections, sides, marched) -> None:
    # one drive (a sweep's point, its cloud): every trajectory is of group 0, no search for groups
    for g in (0,) if len(linear) == 1 else np.unique(groups):
        mask = (groups == g) & (state.labels[ids] == -1)
        if not mask.any():
            continue
        # free_for_ever's proof, compiled (:func:`.books.free_for_ever_flags`)
        orbit = linear[g]
        calm = _compiled(books.free_for_ever_flags)(np.ascontiguousarray(sections, float), np.asarray(sides, float), mask,
                                               float(orbit.nodes[0, 0]), float(orbit.nodes[0, 1]), float(model.free.w2),
                                               float(orbit.low), float(orbit.high), float(model.half_gap))
        if calm.any():
            if g not in quiet:
                quiet[g] = len(state.attractors)
                state.attractors.append(Quiet(int(g), linear[g]))
            chosen = ids[calm]
            state.labels[chosen] = quiet[g]
            state.periods[chosen] = marched


def _distances(history, scale, orbit: Orbit) -> tuple[np.ndarray, np.ndarray]:
    """Scaled distance of each section (periods, m) to the nearest point of ``orbit``, and that
    point's index (compiled: :func:`.books.orbit_distances`)."""
    points = orbit.sections * scale
    return _compiled(books.orbit_distances)(np.ascontiguousarray(history["sections"], float),
                                       np.ascontiguousarray(scale, float), np.ascontiguousarray(points, float))


def _compiled(function):
    """The bookkeeping ``function`` of :mod:`.books`, compiled on the CPU (the history is kept on
    the host)."""
    return target("cpu")(function)


def _label_orbits(state, history, ids, groups, scales, tolerance, marched) -> None:
    """Label the trajectories that are on their way to a known stable orbit (the rule)."""
    span = history["sections"].shape[0]
    for index, orbit in enumerate(state.attractors):
        if not isinstance(orbit, Orbit):
            continue
        mask = (groups == orbit.group) & (state.labels[ids] == -1)
        if not mask.any() or span < 2 * orbit.order:
            continue
        scale = scales[orbit.group]
        sub = {name: values[:, mask] for name, values in history.items()}
        d, nearest = _distances(sub, scale, orbit)
        # the period that ends at the orbit's point i is the orbit's period i - 1
        pattern = np.array(orbit.impacts)
        same_sequence = (sub["impacts"] == pattern[(nearest - 1) % orbit.order]).all(axis=0) & (sub["sides"] == orbit.sides[nearest]).all(axis=0)
        size = max(float(np.abs(orbit.sections * scale).max()), tolerance[orbit.group] / state.settings.tolerance)
        first, last = d[0], d[-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = (last / first) ** (1.0 / (span - 1))
        shrinking = (last < first) & (rate <= orbit.largest + RATE_SLACK) & (last <= LINEAR_REACH * size)
        on = same_sequence & ((last <= tolerance[orbit.group]) | shrinking)
        chosen = ids[mask][on]
        state.labels[chosen] = index
        state.periods[chosen] = marched


def _find_orbits(state, finder, history, ids, groups, scales, settings) -> None:
    """Newton from the trajectories whose returns shrink, for orbits not known yet."""
    sections, impacts, sides = history["sections"], history["impacts"], history["sides"]
    span = sections.shape[0]
    open_ = state.labels[ids] == -1
    if not open_.any():
        return
    chosen: dict[int, list] = {}
    most = min(settings.max_order, (span - 2) // 3)  # the orders 1 to most
    if most < 1:
        return
    # the return over each order at the history's start and at its end, all orders at once (row
    # k is the order k + 1: sections[1:] and, backwards from the last but one, sections[span - 2::-1]),
    # compiled (:func:`.books.shrinking_returns`)
    shrinking = _compiled(books.shrinking_returns)(np.ascontiguousarray(sections, float),
                                              np.ascontiguousarray(scales[groups], float), open_, most, SEED_REACH)
    if not shrinking.any():
        return
    # each trajectory's least order whose returns shrink with the same impacts and sides at that lag
    # in every period (compiled: :func:`.books.converging_orders`), the seeds by order
    orders = _compiled(books.converging_orders)(shrinking, np.ascontiguousarray(impacts, np.int64),
                                           np.ascontiguousarray(sides, np.int64))
    for order in np.unique(orders[orders > 0]).tolist():
        chosen[order] = np.flatnonzero(orders == order).tolist()
    for order, seeds in chosen.items():
        seeds = _spread(seeds, groups, sections[-1], scales, state, settings.seeds)
        if not seeds:
            continue
        seeds = np.array(seeds)
        x, converged = finder.newton(sections[-1][seeds], sides[-1][seeds], groups[seeds], order)
        if not converged.any():
            continue
        found = finder.verify(x[converged], sides[-1][seeds][converged], groups[seeds][converged], order)
        fresh: list = []
        for orbit in found:
            # an orbit without impacts is the neutral family's: only the proof labels it (free_for_ever)
            if orbit is not None and sum(orbit.impacts) and not _known(state.attractors + state.unstable + fresh, orbit, scales,
                                                finder.tolerance):
                fresh.append(orbit)
        if not fresh:
            continue
        finder.multipliers(fresh)
        for orbit in fresh:
            (state.attractors if orbit.stable else state.unstable).append(orbit)


def _spread(seeds, groups, last, scales, state, most: int) -> list:
    """At most ``most`` seeds per drive, none near a known orbit or another seed."""
    picked: list = []
    per_group: dict = {}
    known: dict = {}  # per drive: the known orbits' points, and each point's reach (its orbit's)
    for j in seeds:
        g = groups[j]
        if per_group.get(g, 0) >= most:
            continue
        scale = scales[g]
        if g not in known:
            orbits = [o for o in state.attractors + state.unstable if isinstance(o, Orbit) and o.group == g]
            known[g] = (np.concatenate([o.sections for o in orbits]) if orbits else np.empty((0, 4)),
                        np.concatenate([np.full(o.order, LINEAR_REACH * max(np.abs(o.sections * scale).max(), 1e-300))
                                        for o in orbits]) if orbits else np.empty(0))
        points, reach = known[g]
        near_known = bool((np.abs((points - last[j]) * scale).max(axis=1) <= reach).any())
        near_seed = any(groups[k] == g and np.abs((last[k] - last[j]) * scale).max()
                        <= LINEAR_REACH * np.abs(last[j] * scale).max() for k in picked)
        if not near_known and not near_seed:
            picked.append(j)
            per_group[g] = per_group.get(g, 0) + 1
    return picked


def _known(orbits: list, orbit: Orbit, scales, tolerance) -> bool:
    """``orbit`` passes within 100 tolerances of one of ``orbits``: the same orbit."""
    scale = scales[orbit.group]
    for other in orbits:
        if isinstance(other, Orbit) and other.group == orbit.group:
            if np.abs((other.sections - orbit.sections[0]) * scale).max(axis=1).min() <= 100 * tolerance[orbit.group]:
                return True
    return False
