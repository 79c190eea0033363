"""The event rounds of one hold step: every trajectory that may switch phase in the step goes
from event to event to the step's end (:mod:`.ensemble`, steps 2).

Each round takes the trajectories still inside the step, locates the next switch of each on its
phase's closed form (:mod:`.phases`, :mod:`.events`), moves it there (or to the step's end) and
applies the switch rules (docs/model.md section 3): at an onset the impact mass captures the tip
mass, ``q'+ = (m q' + M_eq p') / (m + M_eq)``; at a separation the tip mass rejoins the main body,
``p'+ = ((M - M_eq) p' + M_eq q') / M``. Under ``voltage_model = 2`` the patch of the barrier in
contact carries its voltage in the contact state, and both decay through the load otherwise.
"""

from __future__ import annotations

import math

from .events import EPS, NOISE_ULPS, ZERO, locate, start_sign

#: Switches of one trajectory at one instant before it is declared degenerate (the core's limit).
MAX_SWITCHES_AT_ONE_INSTANT = 8
#: Rounds of one hold step before the trajectories left in it are declared degenerate.
MAX_ROUNDS = 10_000


def event_rounds(ens, mask, y0, v, h):
    """Take the trajectories of ``ens`` in ``mask`` through their events to the end of the hold
    step (base ``y0 + v t``, length ``h``: floats, or arrays over all trajectories). Writes their
    states back and returns their contact onsets in the step."""
    xp, model = ens.xp, ens.model
    P, DP, Q, DQ, S = (a[mask] for a in (ens.p, ens.dp, ens.q, ens.dq, ens.side))
    VL, VR = (a[mask] for a in ens.volts) if ens.volts is not None else (None, None)
    Y0, V, H = (a if isinstance(a, float) else a[mask] for a in (y0, v, h))
    count = P.shape[0]
    tl = xp.zeros((count,))
    instant = xp.zeros((count,), dtype=xp.int64)
    onsets = xp.zeros((count,), dtype=xp.int64)
    failed = ens.failed[mask]
    live = ~failed
    for _ in range(MAX_ROUNDS):
        if not bool(xp.any(live)):
            break
        sub = (lambda a: a if isinstance(a, float) else a[live])
        p, dp, q, dq, s, t0 = P[live], DP[live], Q[live], DQ[live], S[live], tl[live]
        y_, v_, h_ = sub(Y0), sub(V), sub(H)
        vl, vr = (VL[live], VR[live]) if VL is not None else (None, None)
        base = y_ + v_ * t0
        u, w, du, dw = p - base, q - base, dp - v_, dq - v_
        rem = h_ - t0
        n = p.shape[0]
        t_ev = xp.full((n,), math.inf)
        to = xp.zeros((n,))
        bad = xp.zeros((n,), dtype=xp.bool)
        u1, w1, du1, dw1 = (xp.asarray(a, copy=True) for a in (u, w, du, dw))
        volt_in_contact = None
        free = s == 0.0
        contact = ~free
        if bool(xp.any(free)):
            t_f, to_f, bad_f = _free_events(xp, model, u[free], du[free], w[free], dw[free], rem[free])
            t_ev[free], to[free], bad[free] = t_f, to_f, bad_f
        if bool(xp.any(contact)):
            volts = xp.where(s > 0.0, vr, vl)[contact] if vl is not None else None
            t_c, bad_c, modal = _contact_events(ens, u[contact], du[contact], w[contact], dw[contact], s[contact],
                                                volts, rem[contact])
            t_ev[contact], bad[contact] = t_c, bad_c
        dt = xp.minimum(t_ev, rem)
        switch = (t_ev <= rem) & ~bad
        if bool(xp.any(free)):
            dtf = dt[free]
            uu, dd = model.free.apply(model.free.coefficients(xp, dtf), u[free], du[free])
            u1[free], du1[free], w1[free] = uu, dd, w[free] + dw[free] * dtf
        if bool(xp.any(contact)):
            e = _modal_state(ens, modal, dt[contact])
            sc = s[contact]
            u1[contact], w1[contact], du1[contact], dw1[contact] = e[:, 0], e[:, 1] + sc * model.half_gap, e[:, 2], e[:, 3]
            if vl is not None:
                volt_in_contact = sc * e[:, 4]
        base1 = base + v_ * dt
        p, q, dp, dq = u1 + base1, w1 + base1, du1 + v_, dw1 + v_
        if vl is not None:
            fade = xp.exp(-dt / model.tau_e)
            vl, vr = vl * fade, vr * fade
            if volt_in_contact is not None:
                vl[contact] = xp.where(s[contact] < 0.0, volt_in_contact, vl[contact])
                vr[contact] = xp.where(s[contact] > 0.0, volt_in_contact, vr[contact])
        onset = switch & free
        release = switch & contact
        captured = (model.m * dq + model.M_eq * dp) / (model.m + model.M_eq)
        released = (model.M1 * dp + model.M_eq * dq) / model.M
        dq = xp.where(onset, captured, dq)
        dp = xp.where(release, released, dp)
        s = xp.where(onset, to, xp.where(release, 0.0, s))
        stuck = xp.where(switch & (dt == 0.0), instant[live] + 1, 0)
        bad = bad | (stuck > MAX_SWITCHES_AT_ONE_INSTANT) | ~xp.isfinite(p + q + dp + dq)
        done = ~switch | bad
        t1 = xp.where(switch, t0 + dt, h_ + 0.0 * t0)
        done = done | (t1 >= h_)
        P[live], DP[live], Q[live], DQ[live], S[live], tl[live] = p, dp, q, dq, s, t1
        if VL is not None:
            VL[live], VR[live] = vl, vr
        instant[live] = stuck
        onsets[live] = onsets[live] + xp.astype(onset, xp.int64)
        failed[live] = bad
        live[live] = ~done
    else:
        failed = failed | live
    nan = math.nan
    ens.p[mask] = xp.where(failed, nan, P)
    ens.dp[mask] = xp.where(failed, nan, DP)
    ens.q[mask] = xp.where(failed, nan, Q)
    ens.dq[mask] = xp.where(failed, nan, DQ)
    ens.side[mask] = xp.where(failed, 0.0, S)
    if VL is not None:
        ens.volts[0][mask], ens.volts[1][mask] = VL, VR
    ens.failed[mask] = failed
    return onsets


def _free_events(xp, model, u, du, w, dw, rem):
    """The next contact onset of free trajectories within ``rem`` (s, one per trajectory): its time
    (inf: none), the barrier it reaches, whether its location failed."""
    free, hg = model.free, model.half_gap
    r, dr = w - u, dw - du
    tol = NOISE_ULPS * EPS * (xp.abs(u) + xp.abs(w) + hg)
    zero = xp.maximum(tol, ZERO * 2.0 * hg)
    rate_noise = NOISE_ULPS * EPS * (xp.abs(dw) + xp.abs(du))
    g0 = xp.stack([r - hg, -r - hg])
    dg0 = xp.stack([dr, -dr])
    near = xp.abs(g0) <= zero
    start = xp.stack([start_sign(xp, dr, rate_noise, model.K, model.C, u, du, 1.0),
                      start_sign(xp, -dr, rate_noise, model.K, model.C, u, du, -1.0)])
    now = near & (start > 0.0)
    bound = free.bound_rate * xp.sqrt(du * du + free.w2 * u * u)

    def evaluate(t):
        uu, dd = free.apply(free.coefficients(xp, t), u, du)
        ww = w + dw * t
        rr, drr = ww - uu, dw - dd
        return xp.stack([rr - hg, -rr - hg]), xp.stack([drr, -drr]), NOISE_ULPS * EPS * (xp.abs(uu) + xp.abs(ww) + hg)

    time, which, failed = locate(xp, evaluate, g0, dg0, tol, near & ~now, rem, bound)
    immediate = xp.any(now, axis=0)
    time = xp.where(immediate, 0.0, time)
    right = xp.where(immediate, now[0, :], which == 0)
    side = 2.0 * xp.astype(right, xp.float64) - 1.0
    return time, side, failed & ~immediate


def _contact_events(ens, u, du, w, dw, s, volts, rem):
    """The separation of trajectories in contact within ``rem`` (s): its time (inf: none), whether
    its location failed, and their modal amplitudes (for :func:`_modal_state`)."""
    xp, model = ens.xp, ens.model
    hg = model.half_gap
    columns = [u, w - s * hg, du, dw] + ([s * volts] if volts is not None else [])
    # Row by row (no matrix product: its kernel, and so its last bits, may depend on the batch size).
    alpha = xp.sum(xp.astype(xp.stack(columns, axis=1), xp.complex128)[:, :, None] * ens._q_inv_t[None, ...], axis=1)
    c = alpha * ens._gain
    size = xp.sum(xp.abs(c), axis=1)
    delta, rate = s * (w - u) - hg, s * (dw - du)
    tol = NOISE_ULPS * EPS * (xp.abs(u) + xp.abs(w) + hg + size)
    near = xp.abs(delta) <= xp.maximum(tol, ZERO * 2.0 * hg)
    rate_noise = NOISE_ULPS * EPS * (xp.abs(dw) + xp.abs(du))
    now = near & (start_sign(xp, rate, rate_noise, model.K, model.C, u, du, s) < 0.0)
    bound = xp.sum(xp.abs(c) * ens._lam2, axis=1)
    lam = ens._lam

    def evaluate(t):
        terms = c * xp.exp(lam * xp.astype(t, xp.complex128)[:, None])
        return (xp.stack([-s * xp.real(xp.sum(terms, axis=1))]), xp.stack([-s * xp.real(xp.sum(terms * lam, axis=1))]),
                tol)

    time, _, failed = locate(xp, evaluate, xp.stack([-delta]), xp.stack([-rate]), tol, xp.stack([near & ~now]),
                             rem, bound)
    time = xp.where(now, 0.0, time)
    return time, failed & ~now, alpha


def _modal_state(ens, alpha, t):
    """The contact state ``e(t)`` relative to the rest in contact, (count, size), real."""
    xp = ens.xp
    growth = xp.exp(ens._lam * xp.astype(t, xp.complex128)[:, None])
    return xp.real(xp.sum((alpha * growth)[:, :, None] * ens._q_t[None, ...], axis=1))
