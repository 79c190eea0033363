"""The two phases of one trajectory in closed form (:mod:`..model` gives the formulas and the
constants): free flight of the main mass relative to a ramping base, and contact in modal form from
the modal amplitudes kept in ``work``."""

import math

from ..model import DECAYS_APART
from .layout import A, BETA2, CONTACT_AT, CRITICAL, CS_MODE, GROWTH, LAM, MODES, QM, UNDERDAMPED, USED, W2, WD, WEIGHT
from .registry import source


@source
def free_coefficients(c, t):
    """``(e^{-a t} c(t), e^{-a t} s(t))`` of free flight at ``t`` (s) (``FreeFlow.coefficients``)."""
    mode = c[CS_MODE]
    if mode == CRITICAL:
        bt2 = c[BETA2] * t * t
        cos, sin = 1.0 + bt2 / 2.0, t * (1.0 + bt2 / 6.0)
    elif mode == UNDERDAMPED:
        wd = c[WD]
        cos, sin = math.cos(wd * t), math.sin(wd * t) / wd
    else:
        b = c[WD]
        if c[A] * t > DECAYS_APART:  # the slow and the fast decay apart: cosh would overflow
            slow, apart = math.exp(-c[W2] / (c[A] + b) * t), -math.expm1(-2.0 * b * t)
            return slow * (1.0 - 0.5 * apart), slow * apart / (2.0 * b)
        cos, sin = math.cosh(b * t), math.sinh(b * t) / b
    decay = math.exp(-c[A] * t)
    return decay * cos, decay * sin


@source(inline=True)
def free_apply(c, ec, es, u, du):
    """``(u(t), u'(t))`` (m, m/s) of free flight from ``(u0, u0')`` with the coefficients ``ec, es``
    of :func:`free_coefficients` at ``t`` (``FreeFlow.apply``)."""
    a, w2 = c[A], c[W2]
    return ec * u + es * (a * u + du), ec * du - es * (w2 * u + a * du)


@source
def contact_value(s, c, work, t):
    """The separation's event function ``-delta`` (m) at ``t`` (s) and its rate, in contact with the
    barrier on side ``s``, from the amplitudes ``alpha * gain`` in ``work``; keeps the modes'
    ``e^{lam t}`` in ``work`` for :func:`contact_state`."""
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


@source
def contact_state(c, work, t):
    """The contact state ``e(t)`` relative to the rest in contact, ``(u, w - s d/2, u', w', s V)``
    (m, m/s, V; ``V`` under ``voltage_model = 2``, else 0), from the modal amplitudes in ``work``."""
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
