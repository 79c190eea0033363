"""A 30-digit reference for the piezo-impact damper with the base at rest.

Written from docs/model.md sections 1-3, 5 (quasi-static voltage) and 6; it shares nothing with the
core's integrator, and nothing with the DOP853 reference (``reference.py``) but the order of the
events. Each phase is linear, so its flow is exact: on ``x = (p, q, p', q', 1)``,
``x(t0 + tau) = expm(A tau) x(t0)``, with mpmath's matrix exponential at 30 significant digits.

The events are the roots, on that flow, of the event functions of docs/model.md: onset
``s (q - p) - d/2``, separation ``delta``, the peak of ``delta`` (zero of ``delta'``) and the
maxima of ``p`` (zeros of ``p'``). mpmath's root finder locates each one at 30 digits, starting
from the time the DOP853 reference gives for it; a root more than ``SEED_DISTANCE`` from its
start is an error (another root was found, or the two references disagree on the sequence).
So the DOP853 reference decides which events happen, and this one where they are, to about
1e-25 s: far below the errors of the core and of DOP853, which makes it the truth for both.

Cost: a few seconds for a 2 s run (a matrix exponential per function evaluation).
"""

from __future__ import annotations

import mpmath as mp

from piezo_fmu import Parameters, derive_barrier
from reference import reference_run

DIGITS = 30
#: Largest distance (s) between a root and the DOP853 time it started from.
SEED_DISTANCE = 1e-6


class _Flow:
    """The exact flow of one phase from ``x0`` at ``t0``."""

    def __init__(self, A: mp.matrix, t0: mp.mpf, x0: mp.matrix):
        self.A, self.t0, self.x0 = A, t0, x0

    def at(self, t) -> mp.matrix:
        return mp.expm(self.A * (t - self.t0)) * self.x0


def _matrices(params: Parameters):
    b = derive_barrier(params)
    M, m, K, C = (mp.mpf(v) for v in (params.M, params.m, params.K, params.C))
    M_eq, K_eq, C_eq, half = mp.mpf(b.M_eq), mp.mpf(b.K_eq), mp.mpf(params.C_eq), mp.mpf(params.d) / 2
    free = mp.matrix(5, 5)
    free[0, 2] = free[1, 3] = 1
    free[2, 0], free[2, 2] = -K / M, -C / M
    contact = {}
    for s in (1, -1):
        M1, m1 = M - M_eq, m + M_eq
        A = mp.matrix(5, 5)
        A[0, 2] = A[1, 3] = 1
        # s F = K_eq (q - p) + C_eq (q' - p') - s K_eq d/2, on the main body; -s F on the impacting one.
        force = [-K_eq, K_eq, -C_eq, C_eq, -s * K_eq * half]
        for j in range(5):
            A[2, j] = force[j] / M1
            A[3, j] = -force[j] / m1
        A[2, 0] -= K / M1
        A[2, 2] -= C / M1
        contact[s] = A
    return free, contact, (M, m, M_eq, half, mp.mpf(b.k_V))


def _gap(x: mp.matrix, s: int, half: mp.mpf) -> mp.mpf:
    """``s (q - p) - d/2``: the onset function in free flight, ``delta`` in contact."""
    return s * (x[1] - x[0]) - half


def _root(f, seed: float, what: str) -> mp.mpf:
    # The secant method from two points 1e-10 s apart around the DOP853 time (mpmath's second
    # point would otherwise be 1/4 s away).
    t = mp.findroot(f, (mp.mpf(seed) - mp.mpf("1e-10"), mp.mpf(seed) + mp.mpf("1e-10")))
    if abs(t - seed) > SEED_DISTANCE:
        raise RuntimeError(f"{what}: the root at {mp.nstr(t, 17)} s is {float(abs(t - seed)):.1e} s from the "
                           f"DOP853 time {seed!r} s")
    return t


def exact_run(params: Parameters, t_end: float) -> dict:
    """Impacts ``[{time, side, voltage, duration}]``, maxima ``[(t, p)]`` and ``DI`` (m/s), as floats
    rounded from 30 digits, for the base at rest from ``t = 0`` to ``t_end``."""
    with mp.workdps(DIGITS):
        seeds = reference_run(params, t_end)
        free, contact, (M, m, M_eq, half, k_V) = _matrices(params)
        events = [(i["time"], 0, i) for i in seeds["impacts"] if i["time"] + i["duration"] <= t_end]
        events += [(i["time"] + i["duration"], 1, i) for i in seeds["impacts"] if i["time"] + i["duration"] <= t_end]
        separations = {round(t, 12) for t, kind, _ in events if kind == 1}
        # A maximum at a separation is the corner where p' jumps: it is taken at the separation.
        events += [(t, 2, None) for t, _ in seeds["maxima"] if round(t, 12) not in separations]
        events.sort(key=lambda e: (e[0], e[1]))

        x = mp.matrix([params.p0, params.q0, params.dp0, params.dq0, 1])
        flow = _Flow(free, mp.mpf(0), x)
        impacts, maxima = [], []
        for seed, kind, impact in events:
            if kind == 2:  # a maximum of p: p' falls through zero
                t = _root(lambda t: flow.at(t)[2], seed, "maximum")
                maxima.append((t, flow.at(t)[0]))
            elif kind == 0:  # onset on side s: s (q - p) - d/2 rises through zero
                s = impact["side"]
                t = _root(lambda t: _gap(flow.at(t), s, half), seed, "onset")
                x = flow.at(t)
                x[3] = (m * x[3] + M_eq * x[2]) / (m + M_eq)  # the tip mass is captured
                flow = _Flow(contact[s], t, x)
                end = impact["time"] + impact["duration"]
                # The peak of delta: delta' falls through zero between onset and separation.
                peak = mp.findroot(lambda u: s * (flow.at(u)[3] - flow.at(u)[2]), (t + (end - t) / 8, end - (end - t) / 8),
                                   solver="anderson")
                delta = _gap(flow.at(peak), s, half)
                impacts.append({"time": t, "side": s, "voltage": k_V * delta})
            else:  # separation: delta falls through zero, the tip mass rejoins the main body
                s = impact["side"]
                t = _root(lambda t: _gap(flow.at(t), s, half), seed, "separation")
                x = flow.at(t)
                dp = x[2]
                x[2] = ((M - M_eq) * x[2] + M_eq * x[3]) / M
                if dp > 0 >= x[2]:
                    maxima.append((t, x[0]))  # the corner maximum
                impacts[-1]["duration"] = t - impacts[-1]["time"]
                flow = _Flow(free, t, x)
        positive = [(t, p) for t, p in maxima if p > 0]
        DI = (positive[0][1] - positive[1][1]) / (positive[1][0] - positive[0][0]) if len(positive) >= 2 else mp.nan
        return {"impacts": [{k: (float(v) if k != "side" else v) for k, v in i.items()} for i in impacts],
                "maxima": [(float(t), float(p)) for t, p in maxima], "DI": float(DI)}
