"""Trajectories through whole forcing periods: the march of the CPU (nested loops: the periods, the
hold steps of a period, the rounds of a step) and the Lyapunov pair's march.

A trajectory ``i`` of ``state`` ((7, n): ``p, p', q, q'`` (m, m/s), the phase, the left and right
patch voltages (V)) marches under the drive ``groups[i]``, a row of ``drive`` (:mod:`.layout`),
with ``c`` the damper's constants and ``work`` its scratch row. A trajectory whose events could not
be located is ``failed`` from then on: NaN, and left alone.
"""

import math

from .layout import DECAY, EC, ES, NODES, STEP
from .registry import source
from .rounds import hold_step
from .scalars import INF, NAN, fmax, fmin


@source
def hermite_extremes(p0, v0, p1, v1, h):
    """The largest and smallest value (m) of the cubic Hermite interpolant between ``(p0, v0)`` and
    ``(p1, v1)`` over a step ``h`` (s), ends included: the harness's measure of a motion's extremes."""
    m0, m1 = h * v0, h * v1
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = 6.0 * (p1 - p0) - 4.0 * m0 - 2.0 * m1
    c = m0
    disc = math.sqrt(fmax(b * b - 4.0 * a * c, 0.0))
    quadratic = abs(a) > 1e-300
    safe_a = 2.0 * a if quadratic else 1.0
    safe_b = 1.0 if b == 0.0 else b
    high, low = fmax(p0, p1), fmin(p0, p1)
    for k in range(2):
        root = (-b + disc) / safe_a if k == 0 else (-b - disc) / safe_a
        s = root if quadratic else -c / safe_b
        if s > 0.0 and s < 1.0 and (quadratic or b != 0.0):
            s2 = s * s
            s3 = s2 * s
            value = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1)
            high, low = fmax(high, value), fmin(low, value)
    return high, low


@source(inline=True)
def hold_of(drive, g):
    """The constants of a hold step of drive ``g``: ``(h, e^{-a h} c(h), e^{-a h} s(h), decay)``."""
    return drive[g, STEP], drive[g, EC], drive[g, ES], drive[g, DECAY]


@source
def one_period(observe, x, g, drive, c, work):
    """One forcing period of the motion ``x`` under drive ``g``: ``(x, onsets, failed, top, bottom)``,
    ``top``/``bottom`` the extremes of ``p`` (m, :func:`hermite_extremes` of the hold nodes) when
    ``observe``, else NaN."""
    hold = hold_of(drive, g)
    samples = (drive.shape[1] - NODES - 1) // 2
    onsets = 0
    top = bottom = x[0] if observe else NAN
    for k in range(samples):
        p0, dp0 = x[0], x[1]
        x, count, failed = hold_step(x, drive[g, NODES + k], drive[g, NODES + samples + 1 + k], hold, c, work)
        onsets += count
        if failed:
            return x, onsets, True, NAN, NAN
        if observe:
            high, low = hermite_extremes(p0, dp0, x[0], x[1], hold[0])
            top, bottom = fmax(top, high), fmin(bottom, low)
    return x, onsets, False, top, bottom


@source(inline=True)
def motion_of(state, i):
    """Trajectory ``i``'s motion, read from ``state``."""
    return state[0, i], state[1, i], state[2, i], state[3, i], state[4, i], state[5, i], state[6, i]


@source(inline=True)
def store_motion(state, i, x):
    """Write the motion ``x`` back as trajectory ``i`` of ``state``."""
    state[0, i], state[1, i], state[2, i], state[3, i] = x[0], x[1], x[2], x[3]
    state[4, i], state[5, i], state[6, i] = x[4], x[5], x[6]


@source(inline=True)
def store_period(i, period, x, onsets, top, bottom, sections, sides, impacts, tops, bottoms):
    """Write trajectory ``i``'s section state, phase, onsets and extremes of ``period``."""
    sections[period, i, 0], sections[period, i, 1] = x[0], x[1]
    sections[period, i, 2], sections[period, i, 3] = x[2], x[3]
    sides[period, i] = x[4]
    impacts[period, i] = onsets
    tops[period, i], bottoms[period, i] = top, bottom


@source
def march_one(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work):
    """Trajectory ``i`` through ``sections.shape[0]`` periods, in place; each period's section state
    ``sections`` (periods, n, 4), phase ``sides``, onsets ``impacts`` and, when ``observe``, extremes
    of ``p`` ``tops``/``bottoms`` (NaN without) written."""
    x = motion_of(state, i)
    bad = failed[i]
    g = groups[i]
    for period in range(sections.shape[0]):
        onsets = 0
        top = bottom = NAN
        if not bad:
            x, onsets, bad, top, bottom = one_period(observe, x, g, drive, c, work)
        store_period(i, period, x, onsets, top, bottom, sections, sides, impacts, tops, bottoms)
    store_motion(state, i, x)
    failed[i] = bad


@source
def separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms,
                 work):
    """Trajectory ``i`` beside a companion ``offset[:, i]`` away (the same phase and voltages), brought
    back to the distance ``delta[i]`` (m, distances weighted by ``scale[:, i]``) along their
    separation after every period: the log of each period's stretch ``logs``, ``p`` at each section
    ``samples``, and the trajectory's onsets and extremes. State and offset are left as at the end."""
    x = motion_of(state, i)
    o0, o1, o2, o3 = offset[0, i], offset[1, i], offset[2, i], offset[3, i]
    bad = failed[i]
    g = groups[i]
    d = delta[i]
    for period in range(logs.shape[0]):
        companion = (x[0] + o0, x[1] + o1, x[2] + o2, x[3] + o3, x[4], x[5], x[6])
        onsets = 0
        top = bottom = NAN
        if not bad:
            companion = one_period(False, companion, g, drive, c, work)[0]
            x, onsets, bad, top, bottom = one_period(True, x, g, drive, c, work)
        e0, e1 = (companion[0] - x[0]) * scale[0, i], (companion[1] - x[1]) * scale[1, i]
        e2, e3 = (companion[2] - x[2]) * scale[2, i], (companion[3] - x[3]) * scale[3, i]
        gap = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
        logs[period, i] = math.log(gap / d) if gap > 0.0 else -INF
        ratio = d / gap if gap > 0.0 else NAN
        o0, o1 = (companion[0] - x[0]) * ratio, (companion[1] - x[1]) * ratio
        o2, o3 = (companion[2] - x[2]) * ratio, (companion[3] - x[3]) * ratio
        samples[period, i] = x[0]
        impacts[period, i] = onsets
        tops[period, i], bottoms[period, i] = top, bottom
    store_motion(state, i, x)
    offset[0, i], offset[1, i], offset[2, i], offset[3, i] = o0, o1, o2, o3
    failed[i] = bad
