"""The symmetric two-impact steady state of Masri and Caughey (1966), for base excitation, and
its stability: a closed form independent of the project (docs/model.md section 11).

Nothing here imports ``piezo_fmu`` or ``piezo_fmu_harness``. The model (SI units):

    M p'' + C (p' - y') + K (p - y) = 0,   y = Y sin(w t)     (main mass, absolute p)
    m q'' = 0                                                  (impact mass, absolute q)

and an instantaneous impact with restitution ``e`` whenever ``r = q - p`` reaches ``+-d/2``
moving outwards: momentum ``M p' + m q'`` is kept and the relative velocity ``q' - p'`` is
reversed and multiplied by ``e``.

The orbit: one impact on each barrier per forcing period ``T = 2 pi / w``, half a period apart,
and ``x(t + T/2) = -x(t)`` for ``x = (p, p', q, q')``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class System:
    """The ideal impact damper under base excitation ``y = Y sin(w t)`` (SI)."""

    M: float
    K: float
    C: float
    m: float
    d: float
    e: float
    Y: float
    omega: float

    @property
    def period(self) -> float:
        return 2.0 * math.pi / self.omega

    def transfer(self) -> complex:
        """``H`` with ``P(t) = Im(H Y exp(i w t))`` the main mass's steady response without impacts."""
        w = self.omega
        return (self.K + 1j * self.C * w) / (self.K - self.M * w * w + 1j * self.C * w)

    def particular(self, t):
        """``(P, P')`` of the impact-free steady response at times ``t``."""
        z = self.transfer() * self.Y * np.exp(1j * self.omega * np.asarray(t, float))
        return z.imag, (1j * self.omega * z).imag

    def flow(self, t: float) -> np.ndarray:
        """The 2x2 transition matrix of ``M h'' + C h' + K h = 0`` over time ``t`` (closed form)."""
        wn = math.sqrt(self.K / self.M)
        zeta = self.C / (2.0 * math.sqrt(self.K * self.M))
        if zeta >= 1.0:
            raise ValueError("the closed form here assumes an under-damped main oscillator")
        wd = wn * math.sqrt(1.0 - zeta * zeta)
        decay = math.exp(-zeta * wn * t)
        c, s = math.cos(wd * t), math.sin(wd * t)
        return decay * np.array([[c + zeta * wn / wd * s, s / wd],
                                 [-wn * wn / wd * s, c - zeta * wn / wd * s]])


@dataclass(frozen=True)
class Orbit:
    """One symmetric two-impact orbit, described at its impact on the right barrier (``r = +d/2``)
    at time ``t0`` in ``[0, T)``."""

    system: System
    t0: float
    p0: float            # main mass at the impact, m
    dp_before: float     # p' just before, m/s
    dp_after: float      # p' just after, m/s
    dq_before: float     # q' just before (towards the barrier, > 0), m/s
    dq_after: float      # q' just after (= the flight velocity, < 0), m/s

    @property
    def phase(self) -> float:
        """``w t0`` in ``[0, 2 pi)``: the forcing phase of the impact on the right barrier, rad."""
        return self.system.omega * self.t0

    @property
    def impact_velocity(self) -> float:
        """The impact mass's speed at an impact (absolute), ``|q'|`` in flight, m/s."""
        return abs(self.dq_after)

    @property
    def relative_impact_velocity(self) -> float:
        """``q' - p'`` just before an impact on the right barrier (> 0), m/s."""
        return self.dq_before - self.dp_before

    def state_after(self) -> np.ndarray:
        """``(p, p', q, q')`` just after the impact on the right barrier."""
        return np.array([self.p0, self.dp_after, self.p0 + self.system.d / 2, self.dq_after])

    def main_motion(self, t):
        """``(p, p')`` at times ``t`` in ``[t0, t0 + T/2]`` (between the two impacts)."""
        s = self.system
        P0, dP0 = s.particular(self.t0)
        h0 = np.array([self.p0 - P0, self.dp_after - dP0])
        t = np.atleast_1d(np.asarray(t, float))
        P, dP = s.particular(t)
        h = np.array([s.flow(tau - self.t0) @ h0 for tau in t])
        return P + h[:, 0], dP + h[:, 1]

    @property
    def amplitude(self) -> float:
        """The main mass's amplitude, half its peak-to-peak (= ``max |p|`` by the symmetry), m."""
        s = self.system
        t = self.t0 + np.linspace(0.0, s.period / 2, 4001)
        p, dp = self.main_motion(t)
        best = float(np.max(np.abs(p)))
        # Refine at the interior extrema (p' changes sign) by bisection on p'.
        for i in np.nonzero(np.sign(dp[:-1]) * np.sign(dp[1:]) < 0)[0]:
            a, b = t[i], t[i + 1]
            fa = dp[i]
            for _ in range(60):
                mid = 0.5 * (a + b)
                fm = self.main_motion(mid)[1][0]
                a, b, fa = (mid, b, fm) if fm * fa > 0 else (a, mid, fa)
            best = max(best, abs(self.main_motion(0.5 * (a + b))[0][0]))
        return best

    def admissible(self) -> bool:
        """The impact mass stays inside the gap between the impacts and approaches each barrier
        (no grazing, no other contact): checked on a fine grid of the half period."""
        s = self.system
        if not (self.dq_after < 0 < self.relative_impact_velocity):
            return False
        t = self.t0 + np.linspace(0.0, s.period / 2, 4001)[1:-1]
        p, _ = self.main_motion(t)
        r = self.p0 + s.d / 2 + self.dq_after * (t - self.t0) - p
        return bool(np.all(np.abs(r) < s.d / 2))


def orbits(s: System) -> list[Orbit]:
    """Every symmetric two-impact orbit of ``s`` (0, 1 or 2 of them, before admissibility).

    Unknowns ``p0, v- , v+`` (main mass at impact, its velocity before and after) and the phase,
    written ``c = cos(w t0 + arg H)``, ``s = sin(w t0 + arg H)``. The flight velocity is
    ``u = -(2 p0 + d) w / pi`` (the impact mass crosses from ``p0 + d/2`` to ``-p0 - d/2`` in
    ``T/2``). Momentum, restitution and the symmetry of the main mass's free response after
    ``T/2`` are four equations, linear in ``(p0, v-, v+, c, s)``; with ``c^2 + s^2 = 1`` a quadratic.
    """
    M, m, e, d, w = s.M, s.m, s.e, s.d, s.omega
    H = s.transfer()
    X, theta = abs(H) * s.Y, math.atan2(H.imag, H.real)
    G = s.flow(s.period / 2)
    k = w / math.pi                       # u = -k (2 p0 + d)
    # Columns: p0, v-, v+, c, s ; P0 = X s, P0' = X w c.
    A = np.zeros((4, 5))
    b = np.zeros(4)
    # momentum: M (v+ - v-) = m (q'- - q'+) = -2 m u = 2 m k (2 p0 + d)
    A[0] = [-4 * m * k, -M, M, 0, 0]
    b[0] = 2 * m * k * d
    # restitution: u - v+ = -e (q'- - v-) = e (u + v-)  ->  (1 - e) u - e v- - v+ = 0
    A[1] = [-(1 - e) * 2 * k, -e, -1, 0, 0]
    b[1] = (1 - e) * k * d
    # symmetry: G (p0 - P0, v+ - P0') + (p0 - P0, v- - P0') = 0
    for row in range(2):
        A[2 + row] = [G[row, 0] + (row == 0), (row == 1) * 1.0, G[row, 1],
                      -(G[row, 1] + (row == 1)) * X * w, -(G[row, 0] + (row == 0)) * X]
    # Solve for the first four unknowns with s free: z = z0 + s z1.
    z0 = np.linalg.solve(A[:, :4], b)
    z1 = np.linalg.solve(A[:, :4], -A[:, 4])
    # c = z0[3] + s z1[3];  c^2 + s^2 = 1
    a2, a1, a0 = z1[3] ** 2 + 1, 2 * z0[3] * z1[3], z0[3] ** 2 - 1
    disc = a1 * a1 - 4 * a2 * a0
    found = []
    if disc < 0:
        return found
    for sign in (1.0, -1.0):
        sn = (-a1 + sign * math.sqrt(disc)) / (2 * a2)
        p0, vm, vp, cs = z0 + sn * z1
        t0 = ((math.atan2(sn, cs) - theta) % (2 * math.pi)) / w
        u = -k * (2 * p0 + d)
        found.append(Orbit(s, t0, p0, vm, vp, -u, u))
        if disc == 0:
            break
    return found


def admissible_orbits(s: System) -> list[Orbit]:
    return [o for o in orbits(s) if o.admissible()]


# -- stability: the period map linearised around the orbit ----------------------------------------

def _field(s: System, x: np.ndarray, t: float) -> np.ndarray:
    y, dy = s.Y * math.sin(s.omega * t), s.Y * s.omega * math.cos(s.omega * t)
    return np.array([x[1], -(s.C * (x[1] - dy) + s.K * (x[0] - y)) / s.M, x[3], 0.0])


def _reset(s: System, x: np.ndarray) -> np.ndarray:
    rel = x[3] - x[1]
    total = s.M + s.m
    return np.array([x[0], x[1] + s.m * (1 + s.e) / total * rel, x[2], x[3] - s.M * (1 + s.e) / total * rel])


def saltation(s: System, before: np.ndarray, t: float, side: int) -> np.ndarray:
    """The saltation matrix of the impact at ``g = side (q - p) - d/2 = 0``: the linearised
    jump of a neighbouring trajectory, timing included (Muller 1995; Leine and Nijmeijer)."""
    total = s.M + s.m
    a, b = s.m * (1 + s.e) / total, s.M * (1 + s.e) / total
    D = np.array([[1, 0, 0, 0], [0, 1 - a, 0, a], [0, 0, 1, 0], [0, b, 0, 1 - b]], float)
    grad = side * np.array([-1.0, 0.0, 1.0, 0.0])
    f_minus = _field(s, before, t)
    f_plus = _field(s, _reset(s, before), t)
    return D + np.outer(f_plus - D @ f_minus, grad) / (grad @ f_minus)


def _flight(s: System, dt: float) -> np.ndarray:
    """The 4x4 transition matrix of the free flight over ``dt`` (the forcing drops out)."""
    flight = np.zeros((4, 4))
    flight[:2, :2] = s.flow(dt)
    flight[2:, 2:] = [[1.0, dt], [0.0, 1.0]]
    return flight


def monodromy(orbit: Orbit, offset: float = 0.0) -> np.ndarray:
    """The Jacobian of the period map at the section ``t0 + offset`` (``0 <= offset < T/2``;
    0: just after the right impact): flight to the left impact, its saltation, flight for
    ``T/2``, the right impact's saltation, flight on to the section (all in closed form)."""
    s = orbit.system
    half = s.period / 2
    before_right = np.array([orbit.p0, orbit.dp_before, orbit.p0 + s.d / 2, orbit.dq_before])
    S_right = saltation(s, before_right, orbit.t0, +1)
    S_left = saltation(s, -before_right, orbit.t0 + half, -1)
    return _flight(s, offset) @ S_right @ _flight(s, half) @ S_left @ _flight(s, half - offset)


def multipliers(orbit: Orbit) -> np.ndarray:
    """The Floquet multipliers of the orbit, moduli descending."""
    mu = np.linalg.eigvals(monodromy(orbit))
    return mu[np.argsort(-np.abs(mu))]


# -- an independent check: the ideal impact model integrated event by event -----------------------

def simulate(s: System, x, t: float, duration: float, substeps: int = 200) -> tuple[np.ndarray, float]:
    """March ``x = (p, p', q, q')`` from ``t`` for ``duration`` with the closed-form flight and
    instantaneous impacts (located by bisection to 1e-15 s). Returns ``(x, t)`` at the end."""
    x = np.array(x, float)
    end = t + duration
    dt = s.period / substeps

    def fly(x0, t0, t1):
        P0, dP0 = s.particular(t0)
        P1, dP1 = s.particular(t1)
        h = s.flow(t1 - t0) @ np.array([x0[0] - P0, x0[1] - dP0])
        return np.array([P1 + h[0], dP1 + h[1], x0[2] + x0[3] * (t1 - t0), x0[3]])

    def gap(z):  # > 0 inside
        return s.d / 2 - abs(z[2] - z[0])

    while t < end - 1e-15:
        t1 = min(t + dt, end)
        z = fly(x, t, t1)
        if gap(z) < 0:
            a, b = t, t1
            while b - a > 1e-15 * max(1.0, abs(t)):
                mid = 0.5 * (a + b)
                if gap(fly(x, t, mid)) < 0:
                    b = mid
                else:
                    a = mid
                if b - a < 1e-16:
                    break
            z = fly(x, t, b)
            side = 1 if z[2] - z[0] > 0 else -1
            # Place the impact mass exactly on the barrier, then apply the impact.
            z[2] = z[0] + side * s.d / 2
            if side * (z[3] - z[1]) > 0:
                z = _reset(s, z)
            x, t = z, b
        else:
            x, t = z, t1
    return x, t
