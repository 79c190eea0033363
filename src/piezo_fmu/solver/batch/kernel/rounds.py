"""One hold step of one trajectory: in one closed form of free flight when no contact is possible
in it, else by event rounds, from switch to switch, to the step's end.

Over a hold step the base is the ramp ``y0 + v t`` (:mod:`..drive`), so in coordinates relative to
it every phase is linear and unforced. A round starts where the trajectory stands, locates its
next switch (:mod:`.location`), moves it there or to the step's end in closed form (:mod:`.flows`)
and applies the switch rules (:mod:`.switches`); under ``voltage_model = 2`` the patch of the barrier
in contact carries its voltage in the contact state, and both voltages decay through the load
otherwise.

A trajectory's motion is the tuple ``(p, p', q, q', side, V_left, V_right)`` (m, m/s, the phase: 0
free, +1 or -1 in contact with that barrier, V); a hold step's constants are ``(h, e^{-a h} c(h),
e^{-a h} s(h), decay)`` from its drive's row (:mod:`.layout`).
"""

import math

from ....model.rounding import EPS, MAX_SWITCHES_AT_ONE_INSTANT, NOISE_ULPS, ZERO
from .flows import contact_state, free_apply, free_coefficients
from .layout import BOUND_RATE, COUPLED, FREE_AT, FREE_EC, FREE_ES, HG, M1, M_EQ, MI, MM, TAU_E, W2
from .location import next_event
from .registry import source
from .scalars import NAN, fmax, fmin
from .switches import capture, release

#: Rounds of one hold step before the trajectory is declared degenerate.
MAX_ROUNDS = 10_000
#: How a round ends (:func:`round_end`): another round, the step's end, or a failed location.
GOING, DONE, FAILED = 0, 1, 2


@source(inline=True)
def round_start(x, y0, v, tl, h):
    """A round's start, ``tl`` (s) into a hold step of length ``h`` with base ``y0 + v t``:
    ``(u, u', w, w', rem, base)``, the motion relative to the base, the time left in the step and
    the base there (m)."""
    base = y0 + v * tl
    return x[0] - base, x[1] - v, x[2] - base, x[3] - v, h - tl, base


@source(inline=True)
def contact_voltage(side, vl, vr, c):
    """The voltage (V) of the barrier in contact, as the contact's modes take it (0 one-way)."""
    return (vr if side > 0.0 else vl) if c[COUPLED] != 0.0 else 0.0


@source(inline=True)
def segment(start, x, event, v, c, work):
    """A round's segment: the motion ``x`` moved from the round's ``start`` (:func:`round_start`) to
    its search's ``event`` ``(time, to, failed)`` (:func:`.location.next_event`) or the step's end,
    in closed form, before any switch: ``(moved, dt, switch)``, ``moved`` the motion there (the
    voltages faded, the one in contact the contact's), ``dt`` (s) the segment's length and
    ``switch`` whether the phase switches there."""
    u, du, w, dw, rem, base = start
    side, vl, vr = x[4], x[5], x[6]
    t_ev, bad = event[0], event[2]
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
    elif dt == 0.0:  # a contact that ends as it starts: the state as it stands (the modes' sum rounds it)
        u1, w1, du1, dw1, in_contact = u, w, du, dw, vr if side > 0.0 else vl
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
    return (p, dp, q, dq, side, vl, vr), dt, switch


@source(inline=True)
def switched(moved, dt, switch, event, h, progress, c):
    """A round's end after its :func:`segment`: the switch rules applied to ``moved`` (at an onset to
    the side ``event[1]``), the step's ``progress`` ``(tl, instant, onsets)`` brought on (the time
    into it (s), the switches at the present instant, the contact onsets so far). Returns ``(x,
    progress, status)``, ``status`` :data:`GOING` (another round), :data:`DONE` (the step's end) or
    :data:`FAILED` (the state NaN)."""
    p, dp, q, dq, side, vl, vr = moved
    tl, instant, onsets = progress
    if switch and side == 0.0:
        dq = capture(c[MI], c[M_EQ], dp, dq)[0]
        side = event[1]
        onsets += 1
    elif switch:
        dp = release(c[MM], c[M1], c[M_EQ], dp, dq)[0]
        side = 0.0
    instant = instant + 1 if switch and dt == 0.0 else 0
    bad = event[2] or instant > MAX_SWITCHES_AT_ONE_INSTANT or not math.isfinite(p + q + dp + dq)
    if bad:
        return (NAN, NAN, NAN, NAN, 0.0, vl, vr), (tl, instant, onsets), FAILED
    tl = tl + dt if switch else h + 0.0 * tl
    if not switch or tl >= h:
        return (p, dp, q, dq, side, vl, vr), (tl, instant, onsets), DONE
    return (p, dp, q, dq, side, vl, vr), (tl, instant, onsets), GOING


@source(inline=True)
def round_end(start, x, event, v, h, progress, c, work):
    """A round's end, from its ``start`` (:func:`round_start`), the motion ``x`` it started from and
    its search's ``event`` ``(time, to, failed)`` (:func:`.location.next_event`): the trajectory moved
    to the switch or the step's end (:func:`segment`), the switch rules applied (:func:`switched`).
    Returns ``(x, progress, status)``."""
    moved, dt, switch = segment(start, x, event, v, c, work)
    return switched(moved, dt, switch, event, h, progress, c)


@source
def event_rounds(x, y0, v, h, c, work):
    """A hold step of a trajectory that may switch in it, event by event to the step's end:
    ``(x, onsets, failed)``."""
    progress = (0.0, 0, 0)
    for _ in range(MAX_ROUNDS):
        start = round_start(x, y0, v, progress[0], h)
        phase = (start[0], start[1], start[2], start[3], x[4])
        event = next_event(c, work, phase, contact_voltage(x[4], x[5], x[6], c), start[4])
        x, progress, status = round_end(start, x, event, v, h, progress, c, work)
        if status != GOING:
            return x, progress[2], status == FAILED
    return (NAN, NAN, NAN, NAN, 0.0, x[5], x[6]), progress[2], True


@source(inline=True)
def free_step(x, y0, v, hold, c):
    """A free trajectory's hold step in one closed form: ``(x, possible)``, ``possible`` when a
    contact may fall in the step (the step must then go by event rounds instead)."""
    p, dp, q, dq = x[0], x[1], x[2], x[3]
    h, ec, es, decay = hold
    hg = c[HG]
    u, du = p - y0, dp - v
    u1, du1 = free_apply(c, ec, es, u, du)
    end = y0 + v * h
    p1, dp1, q1 = u1 + end, du1 + v, q + dq * h
    bound = c[BOUND_RATE] * math.sqrt(du * du + c[W2] * u * u)
    reach = fmax(abs(q - p), abs(q1 - p1)) + bound * (h * h / 8.0)
    tol = NOISE_ULPS * EPS * (abs(u) + abs(q - y0) + hg)
    margin = 2.0 * fmax(tol, ZERO * 2.0 * hg)
    return (p1, dp1, q1, dq, x[4], x[5] * decay, x[6] * decay), reach >= hg - margin


@source
def hold_step(x, y0, v, hold, c, work):
    """One hold step of a trajectory (base ``y0 + v t``, constants ``hold``): free flight in one
    closed form when no contact is possible in it, else the event rounds. Returns ``(x, onsets,
    failed)``: the motion at the step's end, the contact onsets in it and whether a location
    failed."""
    if x[4] == 0.0:
        x1, possible = free_step(x, y0, v, hold, c)
        if not possible:
            return x1, 0, False
    return event_rounds(x, y0, v, hold[0], c, work)
