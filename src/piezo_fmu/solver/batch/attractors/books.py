"""The bookkeeping of :func:`.settle.settle` between two blocks of marching, compiled on the CPU
with the kernel: which trajectories' returns shrink (the seeds of Newton), how far each section is
from a known orbit, and which trajectories are proved free for ever.

Each is what a few numpy expressions over ``periods x trajectories x orders x 4`` arrays would
compute, element by element, with numpy's rules for NaN (a largest or smallest value is NaN when any
is; the first NaN is the smallest), so they give numpy's answers bit for bit (the tests hold them to
those expressions) without building the arrays.
"""

import math

import numpy as np

from ..kernel.registry import entry, source
from ..kernel.scalars import NAN, fmax


@source(inline=True)
def largest4(a, b, c, d):
    """numpy's ``max`` of four values: NaN when any is (:func:`..kernel.scalars.fmax`)."""
    return fmax(fmax(a, b), fmax(c, d))


@entry
def shrinking_returns(sections, scale, open_, most, reach):
    """``(most, n)``: whether trajectory ``j``'s return over the order ``k + 1`` shrank by half over
    its history ``sections`` ((periods, n, 4), scaled by ``scale`` (n, 4)) and ends within ``reach``
    times its size (``settle._find_orbits``); False for a trajectory not ``open_``."""
    span, n = sections.shape[0], sections.shape[1]
    out = np.zeros((most, n), np.bool_)
    end = span - 1
    for j in range(n):
        if not open_[j]:
            continue
        s0, s1, s2, s3 = scale[j, 0], scale[j, 1], scale[j, 2], scale[j, 3]
        size = largest4(abs(sections[end, j, 0] * s0), abs(sections[end, j, 1] * s1), abs(sections[end, j, 2] * s2),
                        abs(sections[end, j, 3] * s3))
        for k in range(most):
            first = largest4(abs((sections[k + 1, j, 0] - sections[0, j, 0]) * s0),
                             abs((sections[k + 1, j, 1] - sections[0, j, 1]) * s1),
                             abs((sections[k + 1, j, 2] - sections[0, j, 2]) * s2),
                             abs((sections[k + 1, j, 3] - sections[0, j, 3]) * s3))
            back = span - 2 - k
            last = largest4(abs((sections[end, j, 0] - sections[back, j, 0]) * s0),
                            abs((sections[end, j, 1] - sections[back, j, 1]) * s1),
                            abs((sections[end, j, 2] - sections[back, j, 2]) * s2),
                            abs((sections[end, j, 3] - sections[back, j, 3]) * s3))
            out[k, j] = last < 0.5 * first and last <= reach * size
    return out


@entry
def converging_orders(shrinking, impacts, sides):
    """``(n,)``: the least order ``k + 1`` at which trajectory ``j``'s returns shrink
    (``shrinking[k, j]``) and its history ((periods, n): ``impacts`` and ``sides``) repeats the
    same impacts and sides at that lag in every period; 0 for none (``settle._find_orbits``)."""
    most, n = shrinking.shape[0], shrinking.shape[1]
    span = impacts.shape[0]
    out = np.zeros(n, np.int64)
    for j in range(n):
        for k in range(most):
            if not shrinking[k, j]:
                continue
            order = k + 1
            same = True
            for t in range(order, span):
                if impacts[t, j] != impacts[t - order, j] or sides[t, j] != sides[t - order, j]:
                    same = False
                    break
            if same:
                out[j] = order
                break
    return out


@entry
def orbit_distances(sections, scale, points):
    """The scaled distance of each section ((periods, n, 4), scaled by ``scale`` (4,)) to the
    nearest of an orbit's scaled ``points`` ((m, 4)), and that point's index
    (``settle._distances``)."""
    span, n, m = sections.shape[0], sections.shape[1], points.shape[0]
    gaps = np.empty((span, n))
    nearest = np.zeros((span, n), np.int64)
    s0, s1, s2, s3 = scale[0], scale[1], scale[2], scale[3]
    for t in range(span):
        for j in range(n):
            x0, x1 = sections[t, j, 0] * s0, sections[t, j, 1] * s1
            x2, x3 = sections[t, j, 2] * s2, sections[t, j, 3] * s3
            best = NAN
            which = 0
            for i in range(m):
                gap = largest4(abs(x0 - points[i, 0]), abs(x1 - points[i, 1]), abs(x2 - points[i, 2]),
                               abs(x3 - points[i, 3]))
                if gap != gap:  # numpy's min is NaN and its argmin the first NaN
                    best, which = gap, i
                    break
                if i == 0 or gap < best:
                    best, which = gap, i
            gaps[t, j], nearest[t, j] = best, which
    return gaps, nearest


@entry
def free_for_ever_flags(sections, sides, open_, p0, dp0, w2, low, high, hg):
    """:func:`.orbits.free_for_ever` for the ``open_`` ones of ``sections`` ((n, 4) at the section)
    and ``sides`` ((n,)) against the linear orbit through ``(p0, dp0)`` bounded by ``low`` and
    ``high`` (m): the same operations in the same order, False where not ``open_``. Called once a
    block, for every open trajectory of a cloud: numpy's dozen small array operations and its
    error state cost ten times the arithmetic."""
    n = sections.shape[0]
    out = np.zeros(n, np.bool_)
    root = math.sqrt(w2)
    margin = 1e-9 * hg
    inner, outer = hg - margin, -hg + margin
    for j in range(n):
        if not open_[j]:
            continue
        e, de = sections[j, 0] - p0, sections[j, 1] - dp0
        reach = math.sqrt(de * de + w2 * e * e) / root
        q = sections[j, 2]
        out[j] = sides[j] == 0 and sections[j, 3] == 0.0 and q - low + reach < inner and q - high - reach > outer
    return out
