"""settle's compiled bookkeeping (:mod:`piezo_fmu.solver.batch.kernel_books`) gives the answers of
the numpy expressions it replaced, bit for bit: on histories with NaN sections (a failed
trajectory), ties between an orbit's points, returns that shrink and returns that do not."""

from __future__ import annotations

import numpy as np
import pytest

from piezo_fmu.solver.batch import kernel
from piezo_fmu.solver.batch.settle import SEED_REACH


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
    books = kernel.target("cpu")
    for most in (1, 4, 13):
        expected = numpy_shrinking(sections, scale, open_, most)
        got = books["shrinking_returns"](sections, scale, open_, most, SEED_REACH)
        assert expected.any() and not expected.all()
        assert np.array_equal(got, expected)


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_distances_to_an_orbit_are_numpys(seed):
    sections, rng = histories(seed)
    scale = rng.uniform(0.5, 2.0, 4)
    books = kernel.target("cpu")
    for m in (1, 3, 8):
        points = sections[-1, rng.integers(0, sections.shape[1], m)] * scale
        points[m // 2] = points[0]  # a tie: the first of equal points is the nearest
        if m == 8:
            points[3, 1] = np.nan  # an orbit point's NaN makes every gap NaN from it on
        expected = numpy_distances(sections, scale, points)
        got = books["orbit_distances"](sections, scale, np.ascontiguousarray(points))
        assert np.isnan(expected[0]).any()
        assert np.array_equal(got[0], expected[0], equal_nan=True)
        assert np.array_equal(got[1], expected[1])
