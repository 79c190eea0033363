"""A deterministic synthetic ground-motion record (pure Python, no dependencies).

The ground displacement is a sum of harmonics under a smooth envelope,

    u_g(t) = E(t) * sum_i B_i sin(w_i t + phi_i),

so that its velocity ``v_g`` and acceleration ``a_g`` (the record) follow in closed form, exactly
and consistently: the structure FMU can move its base by ``u_g`` and ``v_g`` while the record
that drives it is ``a_g``.

- Frequencies ``f_i = 0.5, 0.75, ..., 12 Hz`` (47 components).
- Amplitudes from a Kanai-Tajimi acceleration spectrum (firm soil, ``f_g = 4 Hz``,
  ``zeta_g = 0.6``): acceleration amplitude ``A_i = sqrt(2 S(w_i) dw)``, displacement
  ``B_i = A_i / w_i^2``.
- Phases from a fixed 64-bit linear congruential generator (seed 20140101): the same record
  on every machine, with no random-number library involved.
- Envelope: quintic smoothstep rise over ``[0, 0.5 s]``, strong motion to ``2.5 s``, quintic
  decay to ``4 s``, zero after. ``E``, ``E'`` and ``E''`` are continuous, so ``a_g`` is
  continuous; ``u_g(0) = v_g(0) = 0``.
- Scaled so that the peak ``|a_g|`` on a 1 ms grid over the record equals ``pga``.

Inside the structure FMU this file is the top-level module ``primary_structure_ground``.
"""

from __future__ import annotations

import math

F_MIN, F_STEP, N_COMPONENTS = 0.5, 0.25, 47
F_G, ZETA_G = 4.0, 0.6
SEED = 20140101
RISE, STRONG_END, DURATION = 0.5, 2.5, 4.0


def _phases(n: int, seed: int = SEED) -> list[float]:
    """``n`` phases in ``[0, 2 pi)`` from Knuth's MMIX linear congruential generator."""
    state, phases = seed, []
    for _ in range(n):
        state = (6364136223846793005 * state + 1442695040888963407) % 2**64
        phases.append(2.0 * math.pi * (state >> 11) / 2**53)
    return phases


def _smoothstep(s: float) -> tuple[float, float, float]:
    """Quintic smoothstep ``10 s^3 - 15 s^4 + 6 s^5`` and its first two derivatives."""
    if s <= 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    return (s**3 * (10.0 - 15.0 * s + 6.0 * s * s), 30.0 * s * s * (1.0 - s) ** 2,
            60.0 * s * (1.0 - s) * (1.0 - 2.0 * s))


def envelope(t: float) -> tuple[float, float, float]:
    """``(E, E', E'')`` at time ``t`` (s)."""
    if t <= RISE:
        e, de, dde = _smoothstep(t / RISE)
        return e, de / RISE, dde / RISE**2
    if t <= STRONG_END:
        return 1.0, 0.0, 0.0
    span = DURATION - STRONG_END
    e, de, dde = _smoothstep((DURATION - t) / span)
    return e, -de / span, dde / span**2


class GroundMotion:
    """The record scaled to a peak ground acceleration ``pga`` (m/s^2)."""

    def __init__(self, pga: float = 1.0):
        w_g = 2.0 * math.pi * F_G
        dw = 2.0 * math.pi * F_STEP
        self.omegas, self.amplitudes = [], []
        for i in range(N_COMPONENTS):
            w = 2.0 * math.pi * (F_MIN + F_STEP * i)
            kanai_tajimi = (w_g**4 + 4.0 * ZETA_G**2 * w_g**2 * w**2) / (
                (w_g**2 - w**2) ** 2 + 4.0 * ZETA_G**2 * w_g**2 * w**2)
            self.omegas.append(w)
            self.amplitudes.append(math.sqrt(2.0 * kanai_tajimi * dw) / w**2)
        self.phases = _phases(N_COMPONENTS)
        peak = max(abs(self._raw(k * 1e-3)[2]) for k in range(int(DURATION * 1000) + 1))
        scale = pga / peak if peak > 0.0 else 0.0
        self.amplitudes = [b * scale for b in self.amplitudes]

    def _raw(self, t: float) -> tuple[float, float, float]:
        s = ds = dds = 0.0
        for w, b, phi in zip(self.omegas, self.amplitudes, self.phases):
            angle = w * t + phi
            sin_a, cos_a = math.sin(angle), math.cos(angle)
            s += b * sin_a
            ds += b * w * cos_a
            dds -= b * w * w * sin_a
        e, de, dde = envelope(t)
        return e * s, de * s + e * ds, dde * s + 2.0 * de * ds + e * dds

    def __call__(self, t: float) -> tuple[float, float, float]:
        """``(u_g, v_g, a_g)``: ground displacement (m), velocity (m/s), acceleration (m/s^2)."""
        if t >= DURATION:
            t = DURATION  # the ground stays where the record left it
            u, _, _ = self._raw(t)
            return u, 0.0, 0.0
        return self._raw(t)
