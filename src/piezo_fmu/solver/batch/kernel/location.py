"""The phases of one trajectory in closed form and the location of its next switch, as scalar code:
the first half of the compiled kernel's source (issue 32; :mod:`.kernel_source` steps with it, and
:mod:`.kernel` compiles both for the CPU and for a GPU).

These are the closed forms of :mod:`.phases` and the event location of :mod:`.events` for one
trajectory: free flight (the damped oscillator relative to a ramping base), contact in modal form,
and the first zero of an event function found by steps never longer than the first root of
``g + g' dt + B dt^2 / 2`` (``B >= |g''|`` from the present instant on), so that no contact is jumped.

The damper's constants come packed in one array ``c`` (the offsets below): the free flight's and
the switch rules' numbers, then the contact's modes, padded to :data:`MODES` (a padded mode has a
zero amplitude: it adds exact zeros): eigenvalues, ``|lam|^2``, gains, ``Q^-1`` and ``Q``, real parts
then imaginary parts, matrices row by row, each mode's weight and the number of modes used. A
complex pair of modes is carried once, with weight 2: the state is real, so its two terms are each
other's conjugates and their sum is twice the real part of one; a real mode has weight 1.

The rules of :mod:`.kernel_source` hold here too: scalars, ``math`` and arrays passed in, nothing else.
"""

import math

# Offsets into ``c``.
A, W2, BETA2, CS_MODE, WD, BOUND_RATE, HG, MM, M1, MI, M_EQ, KK, CC, COUPLED, TAU_E = range(15)
#: ``CS_MODE``: critical damping (series), underdamped (cos, sin), overdamped (cosh, sinh).
CRITICAL, UNDERDAMPED, OVERDAMPED = 0.0, 1.0, 2.0
#: Contact modes carried (4 states, or 5 with the voltage under ``voltage_model = 2``).
MODES = 5
LAM = 15
LAM2 = LAM + 2 * MODES
GAIN = LAM2 + MODES
QINV = GAIN + 2 * MODES
QM = QINV + 2 * MODES * MODES
WEIGHT = QM + 2 * MODES * MODES
USED = WEIGHT + MODES
CONSTANTS = USED + 1
#: Scratch floats per trajectory: the modal amplitudes alpha and c = alpha * gain (re, im), then the
#: last evaluation of each phase's event function kept for the step that follows it: the modes'
#: ``e^{lam t}`` (re, im) at the time ``CONTACT_AT``, and free flight's coefficients at ``FREE_AT``.
#: The step to a located switch reuses them (the same numbers, not computed twice).
GROWTH = 4 * MODES
CONTACT_AT = 6 * MODES
FREE_AT, FREE_EC, FREE_ES = CONTACT_AT + 1, CONTACT_AT + 2, CONTACT_AT + 3
WORK = CONTACT_AT + 4
# The array engine's constants (:mod:`.events`), repeated: the kernel's source imports nothing but
# math and itself.
NOISE_ULPS = 64.0
EPS = 2.0**-52
ZERO = 1e-13
MAX_ITERATIONS = 1_000_000
INF = math.inf
NAN = math.nan


def fmax(a, b):
    """numpy's ``maximum``: NaN when either is."""
    if a != a or b != b:
        return NAN
    return a if a >= b else b


def fmin(a, b):
    """numpy's ``minimum``: NaN when either is."""
    if a != a or b != b:
        return NAN
    return a if a <= b else b


def sign(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x  # 0.0, -0.0 or NaN, as numpy's sign


def free_coefficients(c, t):
    """``(e^{-a t} c(t), e^{-a t} s(t))`` of free flight (``FreeFlow.coefficients``)."""
    mode = c[CS_MODE]
    if mode == CRITICAL:
        bt2 = c[BETA2] * t * t
        cos, sin = 1.0 + bt2 / 2.0, t * (1.0 + bt2 / 6.0)
    elif mode == UNDERDAMPED:
        wd = c[WD]
        cos, sin = math.cos(wd * t), math.sin(wd * t) / wd
    else:
        b = c[WD]
        cos, sin = math.cosh(b * t), math.sinh(b * t) / b
    decay = math.exp(-c[A] * t)
    return decay * cos, decay * sin


def free_apply(c, ec, es, u, du):
    """``(u(t), u'(t))`` of free flight from ``(u0, u0')`` (``FreeFlow.apply``)."""
    a, w2 = c[A], c[W2]
    return ec * u + es * (a * u + du), ec * du - es * (w2 * u + a * du)


def safe_step(g, dg, bound):
    """The first positive root of ``g + dg dt + bound dt^2 / 2`` (``events.safe_step``)."""
    disc = math.sqrt(fmax(dg * dg - 2.0 * bound * g, 0.0))
    if dg > 0.0:
        return -2.0 * g / (dg + disc)
    if bound > 0.0:
        return (disc - dg) / bound
    if bound != bound:
        return NAN
    return INF


def start_sign(rate, rate_noise, K, C, u, du, barrier):
    """+1 into the barrier just after a phase start, -1 away (``events.start_sign``)."""
    if abs(rate) > rate_noise:
        return sign(rate)
    return sign(barrier * (K * u + C * du))


def free_values(c, work, u, du, w, dw, t):
    """The two event functions of free flight at ``t`` (right onset, left onset), their rates and
    their rounding level."""
    hg = c[HG]
    ec, es = free_coefficients(c, t)
    work[FREE_AT], work[FREE_EC], work[FREE_ES] = t, ec, es
    uu, dd = free_apply(c, ec, es, u, du)
    ww = w + dw * t
    rr, drr = ww - uu, dw - dd
    return rr - hg, -rr - hg, drr, -drr, NOISE_ULPS * EPS * (abs(uu) + abs(ww) + hg)


def contact_value(s, c, work, t):
    """The separation's event function ``-delta`` at ``t`` and its rate, from the modal
    amplitudes ``c = alpha * gain`` in ``work``."""
    total = rate = 0.0
    for j in range(int(c[USED])):
        cr, ci = work[2 * MODES + j], work[3 * MODES + j]
        lr, li = c[LAM + j], c[LAM + MODES + j]
        grow = math.exp(lr * t)
        xr, xi = grow * math.cos(li * t), grow * math.sin(li * t)
        work[GROWTH + j], work[GROWTH + MODES + j] = xr, xi
        tr, ti = cr * xr - ci * xi, cr * xi + ci * xr
        total += c[WEIGHT + j] * tr
        rate += c[WEIGHT + j] * (tr * lr - ti * li)
    work[CONTACT_AT] = t
    return -s * total, -s * rate


def locate_step(contact, t, g_a, g_b, dg_a, dg_b, tol, held_a, held_b, remaining, bound, c, u, du, w, dw, s,
                work):
    """One iteration of :func:`locate`: ``(done, time, which, failed, t, g_a, g_b, dg_a, dg_b, tol)``,
    the last six the search's state for the next iteration (the event functions at ``t``)."""
    fired_a = g_a >= -tol and dg_a > 0.0 and not held_a
    fired_b = g_b >= -tol and dg_b > 0.0 and not held_b
    if fired_a or fired_b:
        return True, t, 0 if fired_a else 1, False, t, g_a, g_b, dg_a, dg_b, tol
    step_a = safe_step(-tol if g_a >= -tol else fmin(g_a, 0.0), dg_a, bound)
    step_b = safe_step(-tol if g_b >= -tol else fmin(g_b, 0.0), dg_b, bound)
    after = t + fmin(step_a, step_b)
    if after >= remaining:
        return True, INF, 0, False, t, g_a, g_b, dg_a, dg_b, tol
    if not math.isfinite(after):
        return True, INF, 0, True, t, g_a, g_b, dg_a, dg_b, tol
    t = after
    if contact:
        g_a, dg_a = contact_value(s, c, work, t)
    else:
        g_a, g_b, dg_a, dg_b, tol = free_values(c, work, u, du, w, dw, t)
    return False, INF, 0, False, t, g_a, g_b, dg_a, dg_b, tol


def locate(contact, g_a, g_b, dg_a, dg_b, tol, near_a, near_b, remaining, bound, c, u, du, w, dw, s, work):
    """The first zero of a trajectory's event functions from its phase start on, within
    ``remaining`` (``events.locate``): ``(time, which, failed)``, ``time`` inf when none. Free
    flight has two functions (``a`` right, ``b`` left); contact one (``a``; ``b`` is ``-inf``)."""
    g_a = 0.0 if near_a else g_a
    g_b = 0.0 if near_b else g_b
    held_a, held_b = near_a, near_b
    t = 0.0
    for _ in range(MAX_ITERATIONS):
        done, time, which, failed, t, g_a, g_b, dg_a, dg_b, tol = locate_step(
            contact, t, g_a, g_b, dg_a, dg_b, tol, held_a, held_b, remaining, bound, c, u, du, w, dw, s, work)
        if done:
            return time, which, failed
        held_a = held_b = False
    return INF, 0, True


def free_start(c, work, u, du, w, dw):
    """The start of :func:`free_event`: ``(now, barrier, g_a, g_b, dg_a, dg_b, tol, near_a, near_b,
    bound)``, ``now`` when an onset is due at once (at ``barrier``), else the search's start."""
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
    return now_a or now_b, 1.0 if now_a else -1.0, g_a, g_b, dr, -dr, tol, near_a, near_b, bound


def free_event(c, work, u, du, w, dw, rem):
    """The next contact onset of a free trajectory within ``rem`` (s): ``(time, barrier,
    failed)``, time inf when none (``rounds._free_events``)."""
    now, barrier, g_a, g_b, dg_a, dg_b, tol, near_a, near_b, bound = free_start(c, work, u, du, w, dw)
    if now:
        return 0.0, barrier, False
    time, which, failed = locate(False, g_a, g_b, dg_a, dg_b, tol, near_a, near_b, rem, bound, c, u, du, w, dw, 0.0,
                                 work)
    return time, 1.0 if which == 0 else -1.0, failed


def contact_start(c, u, du, w, dw, s, volt, work):
    """The start of :func:`contact_event`: ``(now, g, dg, tol, near, bound)``, ``now`` when the
    separation is due at once, else the search's start; leaves the modal amplitudes in ``work``."""
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
    return now, -delta, -rate, tol, near, bound


def contact_event(c, u, du, w, dw, s, volt, rem, work):
    """The separation of a trajectory in contact within ``rem`` (s): ``(time, failed)``; leaves its
    modal amplitudes in ``work`` (``rounds._contact_events``)."""
    now, g, dg, tol, near, bound = contact_start(c, u, du, w, dw, s, volt, work)
    if now:
        return 0.0, False
    time, _, failed = locate(True, g, -INF, dg, 0.0, tol, near, False, rem, bound, c, u, du, w, dw, s, work)
    return time, failed


def contact_state(c, work, t):
    """The contact state ``e(t)`` relative to the rest in contact (``u, w - s d/2, u', w'``, and
    ``s V`` under ``voltage_model = 2``), from the modal amplitudes in ``work``
    (``rounds._modal_state``)."""
    e0 = e1 = e2 = e3 = e4 = 0.0
    m2 = MODES * MODES
    known = work[CONTACT_AT] == t
    for j in range(int(c[USED])):
        ar, ai = work[j], work[MODES + j]
        if known:
            gr, gi = work[GROWTH + j], work[GROWTH + MODES + j]
        else:
            grow = math.exp(c[LAM + j] * t)
            gr, gi = grow * math.cos(c[LAM + MODES + j] * t), grow * math.sin(c[LAM + MODES + j] * t)
        weight = c[WEIGHT + j]
        xr, xi = weight * (ar * gr - ai * gi), weight * (ar * gi + ai * gr)
        e0 += xr * c[QM + j] - xi * c[QM + m2 + j]
        e1 += xr * c[QM + MODES + j] - xi * c[QM + m2 + MODES + j]
        e2 += xr * c[QM + 2 * MODES + j] - xi * c[QM + m2 + 2 * MODES + j]
        e3 += xr * c[QM + 3 * MODES + j] - xi * c[QM + m2 + 3 * MODES + j]
        e4 += xr * c[QM + 4 * MODES + j] - xi * c[QM + m2 + 4 * MODES + j]
    return e0, e1, e2, e3, e4
