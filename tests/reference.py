"""An independent high-accuracy reference for the piezo-impact damper.

Written from docs/model.md sections 1-3, 5 (quasi-static voltage) and 6 only; it shares nothing
with the core's integrator (``src/piezo_fmu/simulator.py``) except ``Parameters`` and
``derive_barrier`` (which give ``M_eq``, ``K_eq`` and ``k_V``).

Method: ``scipy.integrate.solve_ivp(method="DOP853")`` with tight tolerances
(``rtol = 3e-14``, ``atol = 1e-18`` by default; scipy's floor for rtol is 100 eps = 2.2e-14),
phase by phase, in absolute coordinates ``(p, p', q, q')``, with switches located by terminal
events. The tolerances are that tight because impacts amplify errors strongly: in the nominal
case a change of 1e-16 m in ``p0`` moves the last impact time of a 2 s run by ~3e-9 s, and at
``rtol = 1e-12`` the reference's own impact times are off by ~4e-8 s at 2 s.

- free flight (``|r| < d/2``, ``r = q - p``)::

      M p'' + C (p' - v_b) + K (p - y) = 0,      m q'' = 0

  ends when ``r - d/2`` (right, ``s = +1``) or ``-r - d/2`` (left, ``s = -1``) crosses zero
  upward (events with ``direction = +1``). At onset the barrier tip mass ``M_eq`` is captured
  plastically by the impact mass: ``q'+ = (m q' + M_eq p') / (m + M_eq)``, ``p'`` unchanged;
- contact on side ``s`` (``delta = s r - d/2 >= 0``, ``F = K_eq delta + C_eq delta'``)::

      (M - M_eq) p'' + C (p' - v_b) + K (p - y) = s F,      (m + M_eq) q'' = -s F

  ends when ``delta`` crosses zero downward (event ``direction = -1``); the tip mass rejoins
  the main body: ``p'+ = ((M - M_eq) p' + M_eq q') / M``, ``q'`` unchanged.

Records: per contact the onset time, the side, the relative velocity ``r' = q' - p'`` at onset
(before the capture, signed), the maximum deflection (largest ``delta`` at the zeros of
``delta'`` going + to -, located as non-terminal events), ``V_i = k_V delta_max``, and the
duration. Maxima of ``p`` are the zeros of ``p'`` going + to - (non-terminal events in both
phases), plus a maximum at a separation where ``p'`` jumps from ``> 0`` to ``<= 0``.

Event handling after a switch (why nothing re-triggers at the start of a new segment).
scipy detects an event between two accepted steps when ``g_old >= 0 >= g_new`` (falling) or
``g_old <= 0 <= g_new`` (rising), filtered by the event's ``direction``. Right after a switch,
the event that ended the previous phase is not an event of the new phase, and the new
phase's own events start at (or within rounding of) zero but move *away* in the opposite
direction to the one they are armed for:

- after onset, ``delta' = s (q'+ - p') = s m (q' - p') / (m + M_eq) > 0``, so ``delta`` rises
  from 0 while the separation event is armed for falling only;
- after separation, ``s r' = s (q' - p'+) = s (q' - p') (M - M_eq) / M < 0``, so the armed
  rising onset event of the same side sees a falling ``s r - d/2``; the other side is a full
  gap ``d`` away.

So the ``direction`` argument prevents re-triggering, with one catch: scipy's test is
inclusive (``g_old = 0`` counts), so if the *first* step of the new phase is long enough for
``g`` to leave zero and come back across it (a contact of a few tens of microseconds, or a
re-contact right after a shallow separation), the root is put at ``t0``. The first step of a
phase that starts on a surface is therefore limited to a tenth of the return time
``2 |g'| / |g''|`` (``_first_step``), and a switching root found at the start of a phase raises
an error instead of being used. No time window is used for the switching events. The only event that can sit exactly at zero at the start of a segment
and move in its armed direction is ``p' = 0`` (release from rest at ``t = 0``, or a maximum
exactly on a base-hold boundary or produced by a separation jump). A ``p'`` root that lies
exactly at the start of a segment (within ``4 eps`` of ``t0``, which is where brentq puts a
root that sits at the bracket end) is dropped when ``p'(t0) <= 0``: either it is the release
(which is not a maximum, docs/model.md section 6) or it was already recorded at the end of the
previous segment or at the separation jump.

Switch states. The event time from solve_ivp is a root of the step interpolant; the state
there is recomputed by integrating (real steps) from the last accepted step point to that time,
then one Newton correction puts time and state on the (linear) switching surface.

Contacts inside one step. solve_ivp only compares the signs of the event functions at step
points, so an excursion of ``|r|`` beyond ``d/2`` (or of ``delta`` below 0) that starts and ends
within one step would be missed (this happened in the "poor" design at rtol 1e-12: a contact
at relative velocity 2.6 mm/s was skipped). Each phase therefore also records the extrema of
``r`` (free flight, zeros of ``r'``) or of ``delta`` (contact); if ``|r| >= d/2`` (or
``delta <= 0``) at one of them before the detected switch, the crossing is bracketed between the
previous extremum/step point and that extremum, located with brentq on the interpolant, and
taken as the switch.

Base excitation. ``base`` is ``None`` (at rest), a callable ``f(t) -> (y, v_b)`` that is smooth
over the whole run, or a :class:`FirstOrderHold`, whose signal is piecewise affine with jumps
at the hold boundaries; the integration is restarted at each boundary so that DOP853 never
steps across a discontinuity of the right-hand side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from piezo_fmu import Parameters, derive_barrier

DEFAULT_RTOL = 3e-14
DEFAULT_ATOL = 1e-18

FREE = 0


# ----------------------------------------------------------------------------- base signals


def _at_rest(t: float) -> tuple[float, float]:
    return 0.0, 0.0


@dataclass(frozen=True)
class FirstOrderHold:
    """A base signal held affinely over intervals ``[k dt, (k+1) dt)``.

    On interval ``k``: ``y(t) = y_k + v_k (t - t_k)``, ``v_b(t) = v_k`` with ``t_k = k dt`` and
    ``(y_k, v_k) = sample(t_k)``. This is exactly what the core sees when it is advanced by
    ``advance((k+1) dt, y_k, v_k)`` for ``k = 0, 1, ...``.
    """

    dt: float
    sample: Callable[[float], tuple[float, float]]

    def knots(self, t_end: float) -> list[float]:
        n = int(math.ceil(t_end / self.dt - 1e-9))
        ts = [k * self.dt for k in range(n)] + [t_end]
        return ts


def harmonic(Y: float, w: float) -> Callable[[float], tuple[float, float]]:
    """``y = Y sin(w t)``, ``v_b = Y w cos(w t)``."""

    def f(t: float) -> tuple[float, float]:
        return Y * math.sin(w * t), Y * w * math.cos(w * t)

    return f


def _segments(base, t_end: float) -> Iterator[tuple[float, float, Callable]]:
    """Intervals over which the base signal is smooth, with its (y, v) function there."""
    if base is None:
        yield 0.0, t_end, _at_rest
    elif isinstance(base, FirstOrderHold):
        ts = base.knots(t_end)
        for ta, tb in zip(ts[:-1], ts[1:]):
            yk, vk = base.sample(ta)
            yk, vk = float(yk), float(vk)

            def f(t, yk=yk, vk=vk, ta=ta):
                return yk + vk * (t - ta), vk

            yield ta, tb, f
    elif callable(base):
        yield 0.0, t_end, base
    else:
        raise TypeError("base must be None, a callable f(t) -> (y, v) or a FirstOrderHold")


# ----------------------------------------------------------------------------- the reference


@dataclass
class _Contact:
    time: float
    side: int
    rel_velocity: float
    max_deflection: float = 0.0


class ReferenceSimulator:
    """Phase-by-phase DOP853 integration of the piezo-impact damper (see module docstring)."""

    def __init__(self, params: Parameters, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL):
        self.params = params
        bar = derive_barrier(params)
        self.M_eq = float(bar.M_eq)
        self.K_eq = float(bar.K_eq)
        self.k_V = float(bar.k_V)
        self.rtol = rtol
        self.atol = atol
        self.t = 0.0
        self.x = np.array([params.p0, params.dp0, params.q0, params.dq0], dtype=float)
        self.side = FREE
        self.impacts: list[dict] = []
        self.maxima: list[tuple[float, float]] = []
        self.switches: list[dict] = []  # pre/post states of every switch (for sanity checks)
        self.onset_count = 0
        self._contact: _Contact | None = None
        self.nfev = 0
        self.grazing_detections = 0  # switches found inside a step (see _integrate_segment)

    # -- right-hand sides and events ----------------------------------------------------

    def _rhs(self, side: int, basef):
        P = self.params
        M, C, K, m = P.M, P.C, P.K, P.m
        half = P.d / 2
        if side == FREE:
            def f(t, x):
                y, v = basef(t)
                return [x[1], -(C * (x[1] - v) + K * (x[0] - y)) / M, x[3], 0.0]
        else:
            s = side
            Mc = M - self.M_eq
            mc = m + self.M_eq
            Keq, Ceq = self.K_eq, P.C_eq

            def f(t, x):
                y, v = basef(t)
                delta = s * (x[2] - x[0]) - half
                ddelta = s * (x[3] - x[1])
                F = Keq * delta + Ceq * ddelta
                return [x[1], (s * F - C * (x[1] - v) - K * (x[0] - y)) / Mc, x[3], -s * F / mc]
        return f

    def _events(self, side: int):
        """Event functions of a phase, all linear in the state: ``g(t, x) = a . x + c``.

        Free phase: [p' (max of p), r - d/2 (right onset), -r - d/2 (left onset),
        r' (extremum of r: grazing check), ]. Contact phase: [p', delta (separation),
        delta' (max of delta), delta' rising (min of delta: grazing check)].
        """
        half = self.params.d / 2

        def p_max(t, x):  # zeros of p' going + to -
            return x[1]
        p_max.terminal = False
        p_max.direction = -1

        if side == FREE:
            def hit_right(t, x):
                return (x[2] - x[0]) - half
            hit_right.terminal = True
            hit_right.direction = 1

            def hit_left(t, x):
                return -(x[2] - x[0]) - half
            hit_left.terminal = True
            hit_left.direction = 1

            def r_extremum(t, x):  # zeros of r' (where |r| can peak inside one step)
                return x[3] - x[1]
            r_extremum.terminal = False
            r_extremum.direction = 0
            return [p_max, hit_right, hit_left, r_extremum]

        s = side

        def separate(t, x):
            return s * (x[2] - x[0]) - half
        separate.terminal = True
        separate.direction = -1

        def deflection_max(t, x):  # zeros of delta' going + to -
            return s * (x[3] - x[1])
        deflection_max.terminal = False
        deflection_max.direction = -1

        def deflection_min(t, x):  # zeros of delta' going - to + (grazing check)
            return s * (x[3] - x[1])
        deflection_min.terminal = False
        deflection_min.direction = 1
        return [p_max, separate, deflection_max, deflection_min]

    def _switch_function(self, side: int, new_side: int):
        """``(a, c)`` of the switching surface ``g = a . x + c`` (onset into ``new_side``
        from the free phase, or separation from contact on ``side``)."""
        half = self.params.d / 2
        s = new_side if side == FREE else side
        return np.array([-s, 0.0, s, 0.0]), -half

    def _first_step(self, side: int, rhs, t0: float, tb: float):
        """First step for a phase that starts on a switching surface, or None (solver's choice).

        scipy's event test counts ``g_old = 0`` as a crossing in either direction, so if the
        first step of a phase that starts on its surface (``g(t0) = 0``, moving away) is long
        enough for ``g`` to come back across zero (a very shallow contact, or a re-contact just
        after a shallow separation), the root is found at ``t0``. The first step is therefore
        limited to a tenth of the return time ``2 |g'| / |g''|`` of every surface the state sits
        on; the solver's step-size control then grows it within a few steps.
        """
        half = self.params.d / 2
        x = self.x
        sides = (1, -1) if side == FREE else (side,)
        h = math.inf
        f0 = np.asarray(rhs(t0, x), float)
        for s in sides:
            a = np.array([-s, 0.0, s, 0.0])
            g = float(a @ x) - half
            if abs(g) > 1e-12 * half:
                continue
            g1 = float(a @ f0)
            eps = 1e-7 * max(1.0, abs(t0))
            f1 = np.asarray(rhs(t0 + eps, x + eps * f0), float)
            g2 = float(a @ (f1 - f0)) / eps
            if g1 * g2 < 0.0 or g1 == 0.0:
                h = min(h, max(0.1 * 2.0 * abs(g1) / max(abs(g2), 1e-300), 1e-14))
        if not math.isfinite(h):
            return None
        return min(h, tb - t0)

    def _refine_switch(self, sol, t_sw: float, rhs, a: np.ndarray, c: float):
        """State on the switching surface at the switch, from real steps (not the interpolant).

        Re-integrates from the last accepted step point before ``t_sw`` to ``t_sw``, then makes
        one Newton correction of the time on the (linear) surface ``a . x + c = 0`` and moves
        the state along the flow by the same amount (the correction is ~1e-14 s, so the
        neglected second-order term is far below rounding).
        """
        k = int(np.searchsorted(sol.t, t_sw, side="left")) - 1
        k = max(k, 0)
        t_lo, x_lo = float(sol.t[k]), sol.y[:, k]
        if t_sw > t_lo:
            h = t_sw - t_lo
            ref = solve_ivp(rhs, (t_lo, t_sw), x_lo, method="DOP853", rtol=self.rtol,
                            atol=self.atol, first_step=h)
            self.nfev += ref.nfev
            x = ref.y[:, -1].copy()
        else:
            x = np.array(x_lo, float)
        for _ in range(2):
            f = np.asarray(rhs(t_sw, x), float)
            dg = float(a @ f)
            if dg == 0.0:
                break
            dt = -(float(a @ x) + c) / dg
            if abs(dt) > 1e-9:  # the interpolant root must already be close
                raise RuntimeError(f"switch refinement moved the time by {dt:.3e} s at t = {t_sw}")
            t_sw += dt
            x = x + f * dt
        return t_sw, x

    def _integrate_segment(self, tb: float, basef) -> None:
        """Integrate from ``self.t`` to ``tb`` with one smooth base function, switching phases."""
        half = self.params.d / 2
        while True:
            t0 = self.t
            if tb - t0 <= 4 * np.finfo(float).eps * max(1.0, abs(tb)):
                self.t = tb  # nothing left to integrate (an event landed on the boundary)
                return
            side = self.side
            rhs = self._rhs(side, basef)
            sol = solve_ivp(rhs, (t0, tb), self.x, method="DOP853", rtol=self.rtol,
                            atol=self.atol, events=self._events(side), dense_output=True,
                            first_step=self._first_step(side, rhs, t0, tb))
            if sol.status == -1:
                raise RuntimeError(f"reference integration failed at t = {t0}: {sol.message}")
            self.nfev += sol.nfev

            # The switch: the terminal event, or an earlier one that happened inside a single
            # step (|r| peaking above d/2, or delta dipping below 0, between two step points,
            # which the sign test at step points cannot see).
            switch = None  # (time, new_side)
            if sol.status == 1:
                if side == FREE:
                    fired = [(float(sol.t_events[i][0]), 1 if i == 1 else -1)
                             for i in (1, 2) if len(sol.t_events[i])]
                    switch = min(fired)
                else:
                    switch = (float(sol.t_events[1][0]), FREE)
                if switch[0] - t0 <= 4 * np.finfo(float).eps * max(1.0, abs(t0)) and self.switches \
                        and self.switches[-1]["t"] == t0:
                    # A root at the start of a phase is the surface just crossed, seen again
                    # because one step jumped over a whole excursion; _first_step prevents it.
                    raise RuntimeError(f"switching event re-triggered at the start of a phase, t = {t0}")
            # Extrema of r (free) or of delta (contact) inside this solve, in time order: an
            # excursion across the surface lies between one extremum and the next.
            extrema = np.sort(np.concatenate([sol.t_events[3]] if side == FREE
                                             else [sol.t_events[2], sol.t_events[3]]))
            for tm in sol.t_events[3]:
                if switch is not None and tm >= switch[0]:
                    break
                xm = sol.sol(tm)
                r = xm[2] - xm[0]
                if side == FREE and abs(r) >= half:
                    s = 1 if r > 0 else -1

                    def inside(t, s=s):  # > 0 while the impact mass is free of barrier s
                        x = sol.sol(t)
                        return half - s * (x[2] - x[0])
                elif side != FREE and side * r - half <= 0:
                    s = FREE

                    def inside(t):  # > 0 while in contact (delta > 0)
                        x = sol.sol(t)
                        return side * (x[2] - x[0]) - half
                else:
                    continue
                # Bracket the first inside -> outside transition after the previous extremum
                # (or the start) on a grid of the step points subdivided 16 times; the start
                # itself can sit on the surface, so a transition needs an inside point first.
                earlier = extrema[extrema < tm]
                t_a = float(earlier[-1]) if len(earlier) else t0
                knots = np.concatenate([[t_a], sol.t[(sol.t > t_a) & (sol.t < tm)], [tm]])
                grid = np.unique(np.concatenate(
                    [np.linspace(a, b, 17) for a, b in zip(knots[:-1], knots[1:])]))
                bracket = None
                t_in = None
                for t in grid:
                    if inside(t) > 0.0:
                        t_in = t
                    elif t_in is not None:
                        bracket = (t_in, t)
                        break
                if bracket is None:
                    raise RuntimeError(f"cannot bracket a switch inside a step near t = {tm}")
                t_hit = brentq(lambda t: inside(t), *bracket, xtol=1e-17,
                               rtol=4 * np.finfo(float).eps)
                switch = (t_hit, s)
                self.grazing_detections += 1
                break

            t_stop = switch[0] if switch is not None else tb
            start_tol = 4 * np.finfo(float).eps * max(1.0, abs(t0))
            # Maxima of p (event 0, both phases).
            for te, ye in zip(sol.t_events[0], sol.y_events[0]):
                if te > t_stop:
                    break
                if te - t0 <= start_tol and self.x[1] <= 0.0:
                    continue  # release from rest, or already recorded (see module docstring)
                self.maxima.append((float(te), float(ye[0])))
            if side != FREE:
                for te, ye in zip(sol.t_events[2], sol.y_events[2]):
                    if te > t_stop:
                        break
                    delta = side * (ye[2] - ye[0]) - half
                    self._contact.max_deflection = max(self._contact.max_deflection, float(delta))

            if switch is not None:
                a, c = self._switch_function(side, switch[1])
                t_sw, x_sw = self._refine_switch(sol, switch[0], rhs, a, c)
                self.t = t_sw
                if side == FREE:
                    self.x = self._onset(t_sw, x_sw, switch[1])
                    self.side = switch[1]
                else:
                    self.x = self._separation(t_sw, x_sw, side)
                    self.side = FREE
                continue
            self.t = float(sol.t[-1])
            self.x = sol.y[:, -1].copy()
            return

    # -- switches -----------------------------------------------------------------------

    def _onset(self, t: float, x: np.ndarray, side: int) -> np.ndarray:
        m, Meq = self.params.m, self.M_eq
        pre = x.copy()
        rel = x[3] - x[1]
        x = x.copy()
        x[3] = (m * x[3] + Meq * x[1]) / (m + Meq)
        self.onset_count += 1
        self._contact = _Contact(time=t, side=side, rel_velocity=float(rel))
        self.switches.append({"kind": "onset", "t": t, "side": side, "pre": pre, "post": x.copy()})
        return x

    def _separation(self, t: float, x: np.ndarray, side: int) -> np.ndarray:
        M, Meq = self.params.M, self.M_eq
        pre = x.copy()
        x = x.copy()
        x[1] = ((M - Meq) * x[1] + Meq * x[3]) / M
        if pre[1] > 0.0 and x[1] <= 0.0:
            self.maxima.append((t, float(x[0])))
        c = self._contact
        self.impacts.append({
            "time": c.time,
            "side": c.side,
            "rel_velocity": c.rel_velocity,
            "max_deflection": c.max_deflection,
            "voltage": self.k_V * c.max_deflection,
            "duration": t - c.time,
        })
        self._contact = None
        self.switches.append({"kind": "separation", "t": t, "side": side, "pre": pre, "post": x.copy()})
        return x

    # -- integration

    def run(self, t_end: float, base=None) -> "ReferenceSimulator":
        if self.t != 0.0:
            raise RuntimeError("run() starts from t = 0; make a new ReferenceSimulator")
        for ta, tb, f in _segments(base, t_end):
            assert ta == self.t, (ta, self.t)  # segments are contiguous
            self._integrate_segment(tb, f)
        self.t = t_end
        return self

    # -- results ------------------------------------------------------------------------

    def energy(self) -> float:
        """Total mechanical energy (base at rest) in the current phase's mass bookkeeping."""
        P = self.params
        p, dp, q, dq = self.x
        if self.side == FREE:
            return 0.5 * P.M * dp ** 2 + 0.5 * P.m * dq ** 2 + 0.5 * P.K * p ** 2
        delta = self.side * (q - p) - P.d / 2
        return (0.5 * (P.M - self.M_eq) * dp ** 2 + 0.5 * (P.m + self.M_eq) * dq ** 2
                + 0.5 * P.K * p ** 2 + 0.5 * self.K_eq * delta ** 2)

    def results(self) -> dict:
        positive = [(t, p) for t, p in self.maxima if p > 0.0]
        if len(positive) >= 2:
            (t1, p1), (t2, p2) = positive[0], positive[1]
            DI = (p1 - p2) / (t2 - t1)
        else:
            DI = math.nan
        if self.impacts:
            V_rms = math.sqrt(sum(i["voltage"] ** 2 for i in self.impacts) / len(self.impacts))
        else:
            V_rms = 0.0
        return {
            "impacts": list(self.impacts),
            "maxima": list(self.maxima),
            "DI": DI,
            "V_rms": V_rms,
            "P_ave": V_rms ** 2 / self.params.R_load,
            "impact_count": len(self.impacts),
            "onset_count": self.onset_count,
            "in_contact_at_end": self.side != FREE,
            "state": tuple(float(v) for v in self.x),
            "side": self.side,
            "t": self.t,
            "switches": list(self.switches),
            "nfev": self.nfev,
            "grazing_detections": self.grazing_detections,
        }


def reference_run(params: Parameters, t_end: float, base=None, *, rtol: float = DEFAULT_RTOL,
                  atol: float = DEFAULT_ATOL) -> dict:
    """Run the reference from ``t = 0`` to ``t_end``; see :meth:`ReferenceSimulator.results`.

    ``base``: ``None`` (at rest), a smooth ``f(t) -> (y, v_b)``, or a :class:`FirstOrderHold`.
    Keys: ``impacts`` (completed contacts: time, side, rel_velocity, max_deflection, voltage,
    duration), ``maxima`` [(t, p)], ``DI`` (m/s), ``V_rms`` (V), ``P_ave`` (W), ``impact_count``
    (completed contacts), ``onset_count`` (contacts started, including one still open at
    ``t_end``), ``state`` ``(p, p', q, q')`` at ``t_end``, ``side`` (0 free, +-1 in contact).
    """
    if rtol > 1e-11:
        raise ValueError("the reference is meant to run at rtol <= 1e-11")
    return ReferenceSimulator(params, rtol=rtol, atol=atol).run(t_end, base).results()


def reference_state(params: Parameters, t_end: float, base=None, **kw) -> tuple[float, float, float, float]:
    """``(p, p', q, q')`` at ``t_end``."""
    return reference_run(params, t_end, base, **kw)["state"]
