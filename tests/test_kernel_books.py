"""settle's compiled bookkeeping (:mod:`piezo_fmu.solver.batch.attractors.books`) gives the answers of
the numpy expressions it replaced, bit for bit: on histories with NaN sections (a failed
trajectory), ties between an orbit's points, returns that shrink and returns that do not."""

from __future__ import annotations

import numpy as np
import pytest

from piezo_fmu.solver.batch import kernel
from piezo_fmu.solver.batch.attractors import books as source
from piezo_fmu.solver.batch.attractors.settle import SEED_REACH


def compiled(function):
    """The bookkeeping ``function`` as settle runs it: compiled on the CPU."""
    return kernel.target("cpu")(function)


def numpy_shrinking(sections, scale, open_, most):
    """``settle._find_orbits``'s screen as it was written with numpy."""
    span = sections.shape[0]
    size = np.abs(sections[-1] * scale).max(axis=1)
    first = np.abs((sections[1:most + 1] - sections[0]) * scale).max(axis=2)
    last = np.abs((sections[-1] - sections[span - 2::-1][:most]) * scale).max(axis=2)
    return open_ & (last < 0.5 * first) & (last <= SEED_REACH * size)


def numpy_distances(sections, scale, points):
    """``settle._distances`` as it was written with numpy."""
    gaps = np.abs(sections[:, :, None, :] * scale - points[None, None]).max(axis=3)
    return gaps.min(axis=2), gaps.argmin(axis=2)


def histories(seed, span=43, n=300):
    """Sections that converge to period-1 to period-4 returns at various rates, some that do not,
    with NaN in some components and whole periods."""
    rng = np.random.default_rng(seed)
    cycle = rng.normal(size=(4, n, 4))
    order = rng.integers(1, 5, n)
    rate = rng.uniform(0.3, 1.3, n)
    t = np.arange(span)[:, None]
    base = cycle[t % order[None, :], np.arange(n)[None, :]]
    sections = base + (rate[None, :] ** t)[:, :, None] * rng.normal(size=(span, n, 4))
    sections[rng.random((span, n, 4)) < 0.002] = np.nan
    sections[5, :7] = np.nan
    sections[-1, 7:9] = np.nan
    return sections, rng


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_screen_for_newtons_seeds_is_numpys(seed):
    sections, rng = histories(seed)
    scale = rng.uniform(0.5, 2.0, (sections.shape[1], 4))
    open_ = rng.random(sections.shape[1]) < 0.9
    for most in (1, 4, 13):
        expected = numpy_shrinking(sections, scale, open_, most)
        got = compiled(source.shrinking_returns)(sections, scale, open_, most, SEED_REACH)
        assert expected.any() and not expected.all()
        assert np.array_equal(got, expected)


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_distances_to_an_orbit_are_numpys(seed):
    sections, rng = histories(seed)
    scale = rng.uniform(0.5, 2.0, 4)
    for m in (1, 3, 8):
        points = sections[-1, rng.integers(0, sections.shape[1], m)] * scale
        points[m // 2] = points[0]  # a tie: the first of equal points is the nearest
        if m == 8:
            points[3, 1] = np.nan  # an orbit point's NaN makes every gap NaN from it on
        expected = numpy_distances(sections, scale, points)
        got = compiled(source.orbit_distances)(sections, scale, np.ascontiguousarray(points))
        assert np.isnan(expected[0]).any()
        assert np.array_equal(got[0], expected[0], equal_nan=True)
        assert np.array_equal(got[1], expected[1])


def numpy_first_orders(shrinking, impacts, sides):
    """``settle._find_orbits``'s choice of each seed's order as it was written with numpy: the
    orders in turn, each trajectory taken at the first that converges."""
    sequence = 3 * impacts + (np.asarray(sides, np.int64) + 1)
    chosen, taken = {}, set()
    for k in np.flatnonzero(shrinking.any(axis=1)).tolist():
        order = k + 1
        converging = shrinking[k] & (sequence[order:] == sequence[:-order]).all(axis=0)
        for j in np.flatnonzero(converging).tolist():
            if j not in taken:
                taken.add(j)
                chosen.setdefault(order, []).append(j)
    return chosen


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_choice_of_newtons_orders_is_numpys(seed):
    """Impact and side sequences of period 1 to 4, some broken in one period, against returns that
    shrink at several orders: each trajectory at its least order whose sequence repeats."""
    rng = np.random.default_rng(seed)
    span, n, most = 43, 400, 13
    order = rng.integers(1, 5, n)
    pattern = rng.integers(0, 3, (4, n)), rng.integers(-1, 2, (4, n))
    t = np.arange(span)[:, None] % order[None, :]
    impacts, sides = pattern[0][t, np.arange(n)], pattern[1][t, np.arange(n)]
    broken = rng.random(n) < 0.2
    impacts[rng.integers(0, span, n)[broken], np.flatnonzero(broken)] += 1
    shrinking = rng.random((most, n)) < 0.3
    orders = compiled(source.converging_orders)(shrinking, impacts.astype(np.int64), sides.astype(np.int64))
    got = {k: np.flatnonzero(orders == k).tolist() for k in np.unique(orders[orders > 0]).tolist()}
    expected = numpy_first_orders(shrinking, impacts, sides)
    assert len(expected) > 3 and list(got) == list(expected)
    assert got == expected


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_proof_of_free_flight_is_numpys(seed):
    """``free_for_ever`` on states inside, near and beyond its bounds, at rest or not, free or in
    contact, some NaN: the compiled flags are numpy's, False where not asked."""
    from piezo_fmu import Parameters
    from piezo_fmu.solver.batch import HarmonicHold
    from piezo_fmu.solver.batch.attractors.orbits import free_for_ever, linear_orbit
    from piezo_fmu.solver.batch.model import BatchModel

    model = BatchModel.of(Parameters())
    orbit = linear_orbit(model, HarmonicHold(1.25 * 1000**0.5, 1e-3))
    rng = np.random.default_rng(seed)
    n, hg = 4000, model.half_gap
    p = orbit.nodes[0, 0] + rng.normal(scale=hg / 4, size=n)
    dp = orbit.nodes[0, 1] + rng.normal(scale=hg * 2, size=n)
    q = p + rng.uniform(-1.2 * hg, 1.2 * hg, n)
    dq = np.where(rng.random(n) < 0.7, 0.0, rng.normal(size=n))
    states = np.column_stack([p, dp, q, dq])
    states[rng.random((n, 4)) < 0.01] = np.nan
    sides = rng.choice([0.0, 0.0, 0.0, 1.0, -1.0], n)
    asked = rng.random(n) < 0.8
    expected = np.zeros(n, bool)
    expected[asked] = free_for_ever(model, orbit, states[asked], sides[asked])
    got = compiled(source.free_for_ever_flags)(states, sides, asked, float(orbit.nodes[0, 0]),
                                                      float(orbit.nodes[0, 1]), float(model.free.w2),
                                                      float(orbit.low), float(orbit.high), float(hg))
    assert 50 < expected.sum() < asked.sum() - 50
    assert np.array_equal(got, expected)
