"""The energy flows of one trajectory over a segment of its motion (docs/model.md section 5.7, the
scalar core's ledger): the work of the base, the dissipation of the main damper and of the barrier
in contact, the plastic losses at the switches, and the energy harvested in the loads.

Over a segment the base is the ramp ``y0 + v t`` (``v`` constant), so with ``u = p - y``:

- the base's work is ``-v int (K u + C u') dt = -v (K int u dt + C (u(dt) - u(0)))``;
- the main damper dissipates ``C int u'^2 dt``, the barrier in contact ``C_eq int delta'^2 dt``;
- a patch's load takes ``int V^2 / R dt``: a patch out of contact decays, ``V = V0 e^{-t/tau}``, and
  takes ``V0^2 tau (1 - e^{-2 dt/tau}) / (2 R)``; the patch in contact (``voltage_model = 2``)
  carries its voltage in the contact's modes. Under the other models the kernel carries no voltage
  and nothing is harvested here.

Contact's integrals are the closed forms of its modal sums: with ``e_r(t) = sum_j Re(X_rj e^{lam_j
t})``, ``int e_r = sum_j Re(X_rj phi(lam_j))`` and ``int e_a e_b = sum_jk [Re(X_aj X_bk phi(lam_j +
lam_k)) + Re(X_aj conj(X_bk) phi(lam_j + conj(lam_k)))] / 2``, ``phi(z) = (e^{z dt} - 1) / z``
computed without cancellation (:func:`phi`). Free flight's come from an 8-point Gauss-Legendre rule
on pieces of the segment no longer than ``1 / (w_n + 2a)``, where the rule's error is below 1e-18
of the integrand (:func:`free_integrals`); a whole hold step's are computed once
(:func:`.tables.input_hold`).
"""

import math

import numpy as np

from .flows import free_apply, free_coefficients
from .layout import (A, C_EQ, CC, COUPLED, H_C, H_CC, H_CS, H_LOAD, H_S, H_SS, KK, LAM, M1, M_EQ, MI, MM, MODES,
                     QM, R_LOAD, TAU_E, USED, W2, WEIGHT)
from .registry import source
from .switches import capture, release

#: The 8-point Gauss-Legendre rule on [0, 1]: its nodes and weights.
GAUSS_X = tuple(float(x) for x in (np.polynomial.legendre.leggauss(8)[0] + 1.0) / 2.0)
GAUSS_W = tuple(float(w) for w in np.polynomial.legendre.leggauss(8)[1] / 2.0)


@source
def phi(zr, zi, t):
    """``(e^{z t} - 1) / z`` (s) for ``z = zr + i zi`` (1/s) and ``t`` (s), as ``(re, im)``: ``t`` at
    ``z = 0``, and without cancellation for small ``|z t|``."""
    xr, xi = zr * t, zi * t
    if abs(xr) + abs(xi) < 1e-9:
        return t * (1.0 + 0.5 * xr + (xr * xr - xi * xi) / 6.0), t * (0.5 * xi + xr * xi / 3.0)
    grown = math.expm1(xr)
    half = math.sin(0.5 * xi)
    er = grown * math.cos(xi) - 2.0 * half * half
    ei = (grown + 1.0) * math.sin(xi)
    d = zr * zr + zi * zi
    return (er * zr + ei * zi) / d, (ei * zr - er * zi) / d


@source
def free_integrals(c, u, du, t):
    """``(int u dt, int u'^2 dt)`` (m s, m^2/s) over ``[0, t]`` of free flight from ``(u, u')``."""
    rate = math.sqrt(c[W2]) + 2.0 * c[A]
    pieces = max(1, int(math.ceil(rate * t)))
    width = t / pieces
    total = squares = 0.0
    for piece in range(pieces):
        for k in range(8):
            ec, es = free_coefficients(c, width * (piece + GAUSS_X[k]))
            uu, dd = free_apply(c, ec, es, u, du)
            total += GAUSS_W[k] * uu
            squares += GAUSS_W[k] * dd * dd
    return total * width, squares * width


@source(inline=True)
def mode_row(c, work, j, row):
    """``X_rj = weight_j alpha_j Q_rj`` of the contact's mode ``j`` and the state's ``row``, from the
    modal amplitudes in ``work``, as ``(re, im)``."""
    weight = c[WEIGHT + j]
    ar, ai = weight * work[j], weight * work[MODES + j]
    qr, qi = c[QM + row * MODES + j], c[QM + MODES * MODES + row * MODES + j]
    return ar * qr - ai * qi, ar * qi + ai * qr


@source(inline=True)
def product_integral(ar, ai, br, bi, p1r, p1i, p2r, p2i):
    """``int Re(A e^{lam t}) Re(B e^{mu t}) dt`` from ``phi(lam + mu) = p1`` and
    ``phi(lam + conj(mu)) = p2``."""
    return 0.5 * ((ar * br - ai * bi) * p1r - (ar * bi + ai * br) * p1i
                  + (ar * br + ai * bi) * p2r - (ai * br - ar * bi) * p2i)


@source
def contact_integrals(c, work, t):
    """``(int u, int u'^2, int delta'^2, int V^2)`` over ``[0, t]`` of contact (m s, m^2/s, m^2/s,
    V^2 s), from the modal amplitudes in ``work``."""
    used = int(c[USED])
    total = squares = rates = volts = 0.0
    for j in range(used):
        lr, li = c[LAM + j], c[LAM + MODES + j]
        xr, xi = mode_row(c, work, j, 0)
        fr, fi = phi(lr, li, t)
        total += xr * fr - xi * fi
        ur, ui = mode_row(c, work, j, 2)
        wr, wi = mode_row(c, work, j, 3)
        vr, vi = mode_row(c, work, j, 4)
        for k in range(used):
            mr, mi = c[LAM + k], c[LAM + MODES + k]
            p1r, p1i = phi(lr + mr, li + mi, t)
            p2r, p2i = phi(lr + mr, li - mi, t)
            ukr, uki = mode_row(c, work, k, 2)
            wkr, wki = mode_row(c, work, k, 3)
            vkr, vki = mode_row(c, work, k, 4)
            squares += product_integral(ur, ui, ukr, uki, p1r, p1i, p2r, p2i)
            rates += product_integral(wr - ur, wi - ui, wkr - ukr, wki - uki, p1r, p1i, p2r, p2i)
            volts += product_integral(vr, vi, vkr, vki, p1r, p1i, p2r, p2i)
    return total, squares, rates, volts


@source(inline=True)
def decay_integral(volt, t, c):
    """``int V^2 dt`` (V^2 s) over ``[0, t]`` of a patch voltage decaying from ``volt`` (V)."""
    tau = c[TAU_E]
    return volt * volt * tau * 0.5 * -math.expm1(-2.0 * t / tau)


@source
def segment_flows(start, x, moved, dt, v, c, work):
    """The energy flows (J) over a round's segment (:func:`.rounds.segment`): from its ``start``
    (:func:`.rounds.round_start`), the motion ``x`` it started from and the motion ``moved`` at its
    end, ``dt`` (s) long under the base velocity ``v`` (m/s). Returns ``(work, dissipated_C,
    dissipated_Ceq, left, right)``: the base's work, the two dampers' dissipation and the energy into
    the left and right loads."""
    u, du, base = start[0], start[1], start[5]
    side = x[4]
    if side == 0.0:
        total, squares = free_integrals(c, u, du, dt)
        rates = volts = 0.0
    else:
        total, squares, rates, volts = contact_integrals(c, work, dt)
    change = (moved[0] - (base + v * dt)) - u
    left = right = 0.0
    if c[COUPLED] != 0.0:
        load = c[R_LOAD]
        left = (volts if side < 0.0 else decay_integral(x[5], dt, c)) / load
        right = (volts if side > 0.0 else decay_integral(x[6], dt, c)) / load
    return -v * (c[KK] * total + c[CC] * change), c[CC] * squares, c[C_EQ] * rates, left, right


@source(inline=True)
def switch_loss(moved, c):
    """The energy (J) a switch from the motion ``moved`` (just before it) loses plastically: a capture
    in free flight, a release in contact (:mod:`.switches`)."""
    if moved[4] == 0.0:
        return capture(c[MI], c[M_EQ], moved[1], moved[3])[1]
    return release(c[MM], c[M1], c[M_EQ], moved[1], moved[3])[1]


@source(inline=True)
def free_step_flows(x, x1, y0, v, hold, c):
    """The energy flows (J) over a whole hold step in free flight, from the motion ``x`` at its start
    to ``x1`` at its end (base ``y0 + v t``), with free flight's integrals over the step from
    ``hold`` (:func:`.tables.input_hold`): as :func:`segment_flows` returns them."""
    h = hold[0]
    u, du = x[0] - y0, x[1] - v
    g, b = c[A] * u + du, c[W2] * u + c[A] * du
    total = hold[H_C] * u + hold[H_S] * g
    squares = hold[H_CC] * du * du - 2.0 * hold[H_CS] * du * b + hold[H_SS] * b * b
    change = (x1[0] - (y0 + v * h)) - u
    load = hold[H_LOAD]
    return -v * (c[KK] * total + c[CC] * change), c[CC] * squares, 0.0, x[5] * x[5] * load, x[6] * x[6] * load
