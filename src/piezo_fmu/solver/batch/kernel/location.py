"""Where a trajectory's phase switches next: rigorous event location on the closed form of its phase.

A switch is the first zero of an event function ``g`` (negative while the phase lasts): in free
flight the impact mass's distance beyond a barrier, ``+-(w - u) - d/2`` (the contact onsets, right
``a`` and left ``b``); in contact the deflection turned over, ``-delta`` (the separation). With a
bound ``B >= |g''|`` that holds from the present instant on (:mod:`..model`), ``g`` stays below
``g(t) + g'(t) dt + B dt^2 / 2`` over the next ``dt``, so it has no zero before the first root of
that parabola: stepping by it never jumps over a switch, however grazing. Near a simple zero the
steps converge quadratically (Newton's step from the safe side); near a tangency they shrink
geometrically and pass it. A zero is taken when ``g`` is within rounding of 0
(:data:`~piezo_fmu.model.rounding.NOISE_ULPS` ulp of the quantities it is made of) while moving
outwards; a touch within rounding while moving inwards is no switch, as in the scalar core.

**At the start of a phase** (after a switch, or at a hold step where the impact mass sits on a
barrier to rounding) the function is zero, and its sign just after is that of the relative velocity
towards the barrier or, when that is zero to rounding too, of the relative acceleration without the
barrier's force (:func:`.switches.approach_sign`): the scalar core's rule, so that both codes decide
grazing contacts alike.

A phase is the tuple ``(u, u', w, w', s)``: the state relative to the base at the start of the
search (m, m/s) and the side ``s`` in contact (+1 right, -1 left, 0 free). A search's state is
``(t, g_a, g_b, g_a', g_b', tol)``: the time from the phase start (s), the event functions and
their rates there (``g_b`` is ``-inf`` in contact), and their rounding level (m).
"""

import math

from ....model.rounding import EPS, NOISE_ULPS, ZERO
from .flows import contact_value, free_apply, free_coefficients
from .layout import (BOUND_RATE, CC, CONTACT_AT, FREE_AT, FREE_EC, FREE_ES, GAIN, HG, KK, LAM2, MODES, QINV, USED,
                     W2, WEIGHT)
from .registry import source
from .scalars import INF, NAN, fmax, fmin, sign
from .switches import approach_sign

#: Safe steps of one search before the location is declared failed: a simple zero is reached in 3 to
#: 6, a tangency to rounding passed in about 60; a contact resting on its barrier through a hold step
#: is proved to stay there in steps of ``sqrt(2 |g| / B)`` (thousands). The cap stops a search that
#: cannot advance (a step below the rounding of ``t``).
MAX_ITERATIONS = 1_000_000


@source(inline=True)
def safe_step(g, dg, bound):
    """The first positive root of ``g + dg dt + bound dt^2 / 2`` (s): inf when there is none, NaN
    for a NaN bound."""
    disc = math.sqrt(fmax(dg * dg - 2.0 * bound * g, 0.0))
    if dg > 0.0:
        return -2.0 * g / (dg + disc)
    if bound > 0.0:
        return (disc - dg) / bound
    if bound != bound:
        return NAN
    return INF


@source(inline=True)
def start_sign(rate, rate_noise, K, C, u, du, barrier):
    """+1 into the ``barrier`` (+1 right, -1 left) just after a phase start, -1 away, 0 undecided:
    the sign of the relative velocity ``rate`` towards it when that exceeds its rounding level
    ``rate_noise``, else :func:`.switches.approach_sign`."""
    if abs(rate) > rate_noise:
        return sign(rate)
    return approach_sign(K, C, u, du, barrier)


@source
def free_values(c, work, phase, t):
    """The two event functions of free flight at ``t`` (s) (right onset, left onset), their rates and
    their rounding level; keeps free flight's coefficients at ``t`` in ``work``."""
    u, du, w, dw, _ = phase
    hg = c[HG]
    ec, es = free_coefficients(c, t)
    work[FREE_AT], work[FREE_EC], work[FREE_ES] = t, ec, es
    uu, dd = free_apply(c, ec, es, u, du)
    ww = w + dw * t
    rr, drr = ww - uu, dw - dd
    return rr - hg, -rr - hg, drr, -drr, NOISE_ULPS * EPS * (abs(uu) + abs(ww) + hg)


@source(inline=True)
def free_start(c, work, phase):
    """The start of a free flight's search, as :func:`phase_start` returns it."""
    u, du, w, dw, _ = phase
    hg = c[HG]
    work[FREE_AT] = NAN
    r, dr = w - u, dw - du
    tol = NOISE_ULPS * EPS * (abs(u) + abs(w) + hg)
    zero = fmax(tol, ZERO * 2.0 * hg)
    rate_noise = NOISE_ULPS * EPS * (abs(dw) + abs(du))
    g_a, g_b = r - hg, -r - hg
    near_a, near_b = abs(g_a) <= zero, abs(g_b) <= zero
    now_a = near_a and start_sign(dr, rate_noise, c[KK], c[CC], u, du, 1.0) > 0.0
    now_b = near_b and start_sign(-dr, rate_noise, c[KK], c[CC], u, du, -1.0) > 0.0
    bound = c[BOUND_RATE] * math.sqrt(du * du + c[W2] * u * u)
    return now_a or now_b, 1.0 if now_a else -1.0, (g_a, g_b, dr, -dr, tol), near_a, near_b, bound


@source(inline=True)
def contact_start(c, work, phase, volt):
    """The start of a contact's search, as :func:`phase_start` returns it; leaves the modal
    amplitudes of the state (with the patch voltage ``volt`` (V) of the barrier in contact) in
    ``work``."""
    u, du, w, dw, s = phase
    hg = c[HG]
    work[CONTACT_AT] = NAN
    col = (u, w - s * hg, du, dw, s * volt)
    size = bound = 0.0
    for j in range(int(c[USED])):
        ar = 0.0
        ai = 0.0
        for i in range(MODES):
            ar += col[i] * c[QINV + j * MODES + i]
            ai += col[i] * c[QINV + MODES * MODES + j * MODES + i]
        work[j], work[MODES + j] = ar, ai
        cr, ci = ar * c[GAIN + j] - ai * c[GAIN + MODES + j], ar * c[GAIN + MODES + j] + ai * c[GAIN + j]
        work[2 * MODES + j], work[3 * MODES + j] = cr, ci
        size_j = c[WEIGHT + j] * math.hypot(cr, ci)
        size += size_j
        bound += size_j * c[LAM2 + j]
    delta, rate = s * (w - u) - hg, s * (dw - du)
    tol = NOISE_ULPS * EPS * (abs(u) + abs(w) + hg + size)
    near = abs(delta) <= fmax(tol, ZERO * 2.0 * hg)
    rate_noise = NOISE_ULPS * EPS * (abs(dw) + abs(du))
    now = near and start_sign(rate, rate_noise, c[KK], c[CC], u, du, s) < 0.0
    return now, 0.0, (-delta, -INF, -rate, 0.0, tol), near, False, bound


@source(inline=True)
def phase_start(c, work, phase, volt):
    """The start of the search for the switch of ``phase``: ``(now, to, start, near_a, near_b, bound)``,
    ``now`` when the switch is due at once (to the side ``to`` for an onset), else ``start``, the
    event functions, their rates and rounding level ``(g_a, g_b, g_a', g_b', tol)``, which of them
    are zero to rounding at the start (``near_a``, ``near_b``: they cannot fire at once), and the
    bound ``B`` (m/s^2)."""
    if phase[4] != 0.0:
        return contact_start(c, work, phase, volt)
    return free_start(c, work, phase)


@source(inline=True)
def search_start(start, near_a, near_b):
    """A search's state at the phase start, from :func:`phase_start`'s ``start``: a function zero to
    rounding there starts at exactly 0."""
    g_a, g_b, dg_a, dg_b, tol = start
    return 0.0, 0.0 if near_a else g_a, 0.0 if near_b else g_b, dg_a, dg_b, tol


@source(inline=True)
def onset_side(phase, which, to):
    """The side a switch found by a search leads to: the barrier of the function ``which`` (0 right,
    1 left) in free flight, ``to`` (free) in contact."""
    return to if phase[4] != 0.0 else (1.0 if which == 0 else -1.0)


@source(inline=True)
def locate_step(search, held_a, held_b, remaining, bound, phase, c, work):
    """One safe step of a search from its state ``search``: ``(done, time, which, failed, search)``,
    ``time`` (s) the switch of function ``which`` (inf when there is none within ``remaining``
    seconds), ``search`` the state after the step. A function ``held`` (zero to rounding at the
    phase start) cannot fire before the first step."""
    t, g_a, g_b, dg_a, dg_b, tol = search
    fired_a = g_a >= -tol and dg_a > 0.0 and not held_a
    fired_b = g_b >= -tol and dg_b > 0.0 and not held_b
    if fired_a or fired_b:
        return True, t, 0 if fired_a else 1, False, search
    step_a = safe_step(-tol if g_a >= -tol else fmin(g_a, 0.0), dg_a, bound)
    step_b = safe_step(-tol if g_b >= -tol else fmin(g_b, 0.0), dg_b, bound)
    after = t + fmin(step_a, step_b)
    if after >= remaining:
        return True, INF, 0, False, search
    if not math.isfinite(after):
        return True, INF, 0, True, search
    t = after
    s = phase[4]
    if s != 0.0:
        g_a, dg_a = contact_value(s, c, work, t)
    else:
        g_a, g_b, dg_a, dg_b, tol = free_values(c, work, phase, t)
    return False, INF, 0, False, (t, g_a, g_b, dg_a, dg_b, tol)


@source
def locate(start, near_a, near_b, remaining, bound, phase, c, work):
    """The first switch of ``phase`` within ``remaining`` (s), from :func:`phase_start`'s values:
    ``(time, which, failed)``, ``time`` inf when there is none."""
    search = search_start(start, near_a, near_b)
    held_a, held_b = near_a, near_b
    for _ in range(MAX_ITERATIONS):
        done, time, which, failed, search = locate_step(search, held_a, held_b, remaining, bound, phase, c, work)
        if done:
            return time, which, failed
        held_a = held_b = False
    return INF, 0, True


@source
def next_event(c, work, phase, volt, remaining):
    """The next switch of ``phase`` within ``remaining`` (s): ``(time, to, failed)``, ``time`` inf
    when there is none, ``to`` the side it leads to; ``volt`` (V) the patch voltage of the barrier
    in contact. Leaves in ``work`` what the step to it reuses."""
    now, to, start, near_a, near_b, bound = phase_start(c, work, phase, volt)
    if now:
        return 0.0, to, False
    time, which, failed = locate(start, near_a, near_b, remaining, bound, phase, c, work)
    return time, onset_side(phase, which, to), failed
