"""The motion of one trajectory through its hold steps, as scalar code: the source of the compiled
kernel (issue 32), for the CPU and for a GPU alike (:mod:`.kernel` compiles these functions twice).

Everything here and in :mod:`.kernel_phases` is the physics of :mod:`.phases`, :mod:`.events` and
:mod:`.rounds` (the array engine), written for one trajectory: free flight and contact in closed
form, the rigorous event location (a step never longer than the first root of
``g + g' dt + B dt^2 / 2``), the start-of-phase rule and the switch rules, and the first-order-hold
drive. It is the array engine's motion, with
other roundings: the sums over the contact's modes run in order here and pairwise in numpy, and
``cos`` and ``exp`` are the C library's here and numpy's there (both differ in the last bit).

The rules that make the same source compile for both targets: only scalars, ``math``, tuples and
arrays passed in (a scratch row ``work`` of ``WORK`` floats for the contact's modal amplitudes);
no allocation, no exception, no numpy call; complex numbers as pairs of floats. Run as plain Python
(slowly), these functions are the kernel itself: the tests use that to read it.

The damper's constants come packed in one array ``c`` (:mod:`.kernel_phases`); the drives as one
row each of ``drive``: the hold step, its free-flight coefficients and voltage decay, the ``N + 1``
node values and the ``N`` slopes.
"""

import math

from .kernel_phases import (COUPLED, EPS, FREE_AT, FREE_EC, FREE_ES, HG, INF, M1, M_EQ, MI, MM, NAN, NOISE_ULPS,
                            TAU_E, W2, ZERO, BOUND_RATE, contact_event, contact_state, fmax, fmin, free_apply,
                            free_coefficients, free_event)

#: Switches of one trajectory at one instant before it is declared degenerate (the core's limit).
MAX_SWITCHES_AT_ONE_INSTANT = 8
#: Rounds of one hold step before the trajectory is declared degenerate.
MAX_ROUNDS = 10_000
# Offsets into a row of ``drive``: the step (s), ``e^{-a h} c(h)``, ``e^{-a h} s(h)``, the voltage's
# decay over a step, then the nodes (m) and the slopes (m/s).
STEP, EC, ES, DECAY, NODES = range(5)
#: How a round ends (:func:`round_end`): another round, the step's end, or a failed location.
GOING, DONE, FAILED = 0, 1, 2


def round_start(p, dp, q, dq, y0, v, tl, h):
    """A round's state relative to the base at ``tl`` into the step: ``(u, u', w, w', rem, base)``."""
    base = y0 + v * tl
    return p - base, dp - v, q - base, dq - v, h - tl, base


def round_end(u, du, w, dw, rem, base, side, vl, vr, v, h, tl, instant, onsets, t_ev, to, bad, c, work):
    """A round's end, from its start (:func:`round_start`'s values) and its event search's result
    ``t_ev`` (s, inf when none within the step), ``to`` (the barrier of an onset) and ``bad``: the
    trajectory moved to the event or the step's end, the switch rules applied. Returns ``(p, p', q,
    q', side, vl, vr, tl, instant, onsets, status)``, ``status`` :data:`GOING` (another round),
    :data:`DONE` (the step's end) or :data:`FAILED` (the state NaN)."""
    hg = c[HG]
    coupled = c[COUPLED] != 0.0
    free = side == 0.0
    dt = fmin(t_ev, rem)
    switch = t_ev <= rem and not bad
    in_contact = 0.0
    if free:
        if work[FREE_AT] == dt:  # the location's last evaluation: the switch
            ec, es = work[FREE_EC], work[FREE_ES]
        else:
            ec, es = free_coefficients(c, dt)
        u1, du1 = free_apply(c, ec, es, u, du)
        w1, dw1 = w + dw * dt, dw
    else:
        u1, w1, du1, dw1, in_contact = contact_state(c, work, dt)
        w1 += side * hg
        in_contact *= side
    base1 = base + v * dt
    p, q, dp, dq = u1 + base1, w1 + base1, du1 + v, dw1 + v
    if coupled:
        fade = math.exp(-dt / c[TAU_E])
        vl, vr = vl * fade, vr * fade
        if not free:
            if side < 0.0:
                vl = in_contact
            else:
                vr = in_contact
    onset = switch and free
    release = switch and not free
    if onset:
        dq = (c[MI] * dq + c[M_EQ] * dp) / (c[MI] + c[M_EQ])
        side = to
        onsets += 1
    elif release:
        dp = (c[M1] * dp + c[M_EQ] * dq) / c[MM]
        side = 0.0
    instant = instant + 1 if switch and dt == 0.0 else 0
    bad = bad or instant > MAX_SWITCHES_AT_ONE_INSTANT or not math.isfinite(p + q + dp + dq)
    if bad:
        return NAN, NAN, NAN, NAN, 0.0, vl, vr, tl, instant, onsets, FAILED
    tl = tl + dt if switch else h + 0.0 * tl
    if not switch or tl >= h:
        return p, dp, q, dq, side, vl, vr, tl, instant, onsets, DONE
    return p, dp, q, dq, side, vl, vr, tl, instant, onsets, GOING


def contact_voltage(side, vl, vr, c):
    """The voltage of the barrier in contact, as the contact's modes take it (0 one-way)."""
    return (vr if side > 0.0 else vl) if c[COUPLED] != 0.0 else 0.0


def event_rounds(p, dp, q, dq, side, vl, vr, y0, v, h, c, work):
    """A hold step of a trajectory that may switch in it, event by event to the step's end
    (``rounds.event_rounds``): ``(p, p', q, q', side, vl, vr, onsets, failed)``."""
    tl = 0.0
    instant = 0
    onsets = 0
    for _ in range(MAX_ROUNDS):
        u, du, w, dw, rem, base = round_start(p, dp, q, dq, y0, v, tl, h)
        to = 0.0
        if side == 0.0:
            t_ev, to, bad = free_event(c, work, u, du, w, dw, rem)
        else:
            t_ev, bad = contact_event(c, u, du, w, dw, side, contact_voltage(side, vl, vr, c), rem, work)
        p, dp, q, dq, side, vl, vr, tl, instant, onsets, status = round_end(
            u, du, w, dw, rem, base, side, vl, vr, v, h, tl, instant, onsets, t_ev, to, bad, c, work)
        if status == FAILED:
            return NAN, NAN, NAN, NAN, 0.0, vl, vr, onsets, True
        if status == DONE:
            return p, dp, q, dq, side, vl, vr, onsets, False
    return NAN, NAN, NAN, NAN, 0.0, vl, vr, onsets, True


def free_step(p, dp, q, dq, y0, v, h, ec, es, c):
    """A hold step in one closed form of free flight: ``(p, p', q, q', possible)``, ``possible``
    when a contact may fall in the step (then the step must go by event rounds instead)."""
    hg = c[HG]
    u, du = p - y0, dp - v
    u1, du1 = free_apply(c, ec, es, u, du)
    end = y0 + v * h
    p1, dp1, q1 = u1 + end, du1 + v, q + dq * h
    bound = c[BOUND_RATE] * math.sqrt(du * du + c[W2] * u * u)
    reach = fmax(abs(q - p), abs(q1 - p1)) + bound * (h * h / 8.0)
    tol = NOISE_ULPS * EPS * (abs(u) + abs(q - y0) + hg)
    margin = 2.0 * fmax(tol, ZERO * 2.0 * hg)
    return p1, dp1, q1, dq, reach >= hg - margin


def hold_step(p, dp, q, dq, side, vl, vr, y0, v, h, ec, es, decay, c, work):
    """One hold step (base ``y0 + v t`` over ``h``): free flight in one closed form when no contact
    is possible in it, else the event rounds (``Ensemble._step``). Returns the new state, the
    contact onsets in the step and whether the location failed."""
    if side == 0.0:
        p1, dp1, q1, dq1, possible = free_step(p, dp, q, dq, y0, v, h, ec, es, c)
        if not possible:
            return p1, dp1, q1, dq1, side, vl * decay, vr * decay, 0, False
    return event_rounds(p, dp, q, dq, side, vl, vr, y0, v, h, c, work)


def hermite_extremes(p0, v0, p1, v1, h):
    """The largest and smallest value of the cubic Hermite interpolant over a step
    (``ensemble.hermite_extremes``)."""
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


def one_period(observe, p, dp, q, dq, side, vl, vr, g, drive, c,
               work):
    """One forcing period of a trajectory under drive ``g``: ``(p, p', q, q', side, vl, vr, onsets,
    failed, top, bottom)``, ``top``/``bottom`` the extremes of ``p`` (the Hermite interpolant of the
    hold nodes) when ``observe``, else NaN."""
    h, ec, es, decay = drive[g, STEP], drive[g, EC], drive[g, ES], drive[g, DECAY]
    samples = (drive.shape[1] - NODES - 1) // 2
    onsets = 0
    top = bottom = p if observe else NAN
    for k in range(samples):
        p0, dp0 = p, dp
        p, dp, q, dq, side, vl, vr, count, failed = hold_step(p, dp, q, dq, side, vl, vr, drive[g, NODES + k],
                                                              drive[g, NODES + samples + 1 + k], h, ec, es, decay,
                                                              c, work)
        onsets += count
        if failed:
            return NAN, NAN, NAN, NAN, 0.0, vl, vr, onsets, True, NAN, NAN
        if observe:
            high, low = hermite_extremes(p0, dp0, p, dp, h)
            top, bottom = fmax(top, high), fmin(bottom, low)
    return p, dp, q, dq, side, vl, vr, onsets, False, top, bottom


def march_one(observe, i, state, failed, groups, drive, c, sections,
              sides, impacts, tops, bottoms, work):
    """Trajectory ``i`` of ``state`` ((7, n): ``p, p', q, q'``, side, left and right voltage) through
    ``sections.shape[0]`` periods, in place; each period's section state, phase, onsets and (when
    ``observe``) extremes of ``p`` written to the outputs. A failed trajectory stays NaN."""
    p, dp, q, dq, side, vl, vr = (state[0, i], state[1, i], state[2, i], state[3, i], state[4, i], state[5, i],
                                  state[6, i])
    bad = failed[i]
    g = groups[i]
    for period in range(sections.shape[0]):
        onsets = 0
        top = bottom = NAN
        if not bad:
            p, dp, q, dq, side, vl, vr, onsets, bad, top, bottom = one_period(
                observe, p, dp, q, dq, side, vl, vr, g, drive, c, work)
        sections[period, i, 0], sections[period, i, 1] = p, dp
        sections[period, i, 2], sections[period, i, 3] = q, dq
        sides[period, i] = side
        impacts[period, i] = onsets
        tops[period, i], bottoms[period, i] = top, bottom
    state[0, i], state[1, i], state[2, i], state[3, i] = p, dp, q, dq
    state[4, i], state[5, i], state[6, i] = side, vl, vr
    failed[i] = bad


def separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms, work):
    """Trajectory ``i`` beside a companion ``offset[:, i]`` away (the same phase and voltages),
    brought back to the distance ``delta[i]`` (m, with ``scale``) along their separation after every
    period (``trajectories.measure``): the log of each period's stretch, ``p`` at each section, the
    onsets and extremes of the trajectory. State and offset are left as at the end."""
    p, dp, q, dq, side, vl, vr = (state[0, i], state[1, i], state[2, i], state[3, i], state[4, i], state[5, i],
                                  state[6, i])
    o0, o1, o2, o3 = offset[0, i], offset[1, i], offset[2, i], offset[3, i]
    bad = failed[i]
    g = groups[i]
    d = delta[i]
    for period in range(logs.shape[0]):
        c0, c1, c2, c3 = p + o0, dp + o1, q + o2, dq + o3
        onsets = 0
        top = bottom = NAN
        if not bad:
            c0, c1, c2, c3, _, _, _, _, _, _, _ = one_period(False, c0, c1, c2, c3, side, vl, vr, g, drive, c, work)
            p, dp, q, dq, side, vl, vr, onsets, bad, top, bottom = one_period(True, p, dp, q, dq, side, vl, vr, g, drive,
                                                                              c, work)
        e0, e1 = (c0 - p) * scale[0, i], (c1 - dp) * scale[1, i]
        e2, e3 = (c2 - q) * scale[2, i], (c3 - dq) * scale[3, i]
        gap = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
        logs[period, i] = math.log(gap / d) if gap > 0.0 else -INF
        ratio = d / gap if gap > 0.0 else NAN
        o0, o1, o2, o3 = (c0 - p) * ratio, (c1 - dp) * ratio, (c2 - q) * ratio, (c3 - dq) * ratio
        samples[period, i] = p
        impacts[period, i] = onsets
        tops[period, i], bottoms[period, i] = top, bottom
    state[0, i], state[1, i], state[2, i], state[3, i] = p, dp, q, dq
    state[4, i], state[5, i], state[6, i] = side, vl, vr
    offset[0, i], offset[1, i], offset[2, i], offset[3, i] = o0, o1, o2, o3
    failed[i] = bad
