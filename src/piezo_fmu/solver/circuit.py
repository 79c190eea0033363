"""The patch voltage as a circuit (docs/model.md section 5, eqs. 20-21): exact on every bracket.

The patch is a capacitance ``C_p`` across the load ``R``, driven by the barrier's deflection rate:
``C_p V' + V / R = chi delta'``. Its electrical rate ``1 / (R C_p)`` (5.6e4 1/s at the nominal
load, up to 1e9 1/s for small loads) is far above the mechanical ones, so ``V`` is kept out of
the Taylor-exact brackets of ``propagation.py`` whenever it can be:

- between contacts a barrier's voltage decays as ``V0 exp(-t / (R C_p))``, in closed form, and
  its harvested energy is ``0.5 C_p V0^2 (1 - exp(-2 t / (R C_p)))``
  (:func:`piezo_fmu.model.voltage.decay`);
- in contact under the one-way model (``voltage_model = 1``) the mechanics are untouched and ``V``
  is the exact solution of a scalar linear ODE driven by the bracket polynomial ``delta'(s)``.
  In normalised time ``s`` (``t = t0 + s tau``): ``dV/ds = -lam V + k D(s)``, ``lam = tau/(R C_p)``,
  ``k = tau chi / C_p``, ``D = delta'`` (m/s). Its solution on the bracket is
  ``V(s) = P(s) + E exp(-lam s)`` (:func:`driven`), where

  * for ``lam > LAM_SPLIT``, ``P = k sum_j (-1)^j D^(j) / lam^(j+1)`` is the polynomial particular
    solution (a finite sum: ``D`` is a polynomial) and ``E = V0 - P(0)``; the sum converges like
    ``(THETA / lam)^j``, so it has no cancellation;
  * for ``lam <= LAM_SPLIT`` the exponential is as slow as the mechanics, and ``V`` is summed as
    one more Taylor series on the bracket (``E = 0``): exact to rounding, like the state;

- in contact under the coupled model (``voltage_model = 2``) ``V`` is a column of the contact
  state itself and ``P`` is that column (``E = 0``).

On a bracket :class:`Piece` holds the voltage and the exact primitives of the harvested power
``V^2 / R`` and of the converted power ``chi V delta'`` (both J, from the bracket start): the
polynomial parts by ``propagation.primitive_of_square`` and friends, the exponential parts by
``int_0^s f(r) exp(-lam r) dr = Q(0) - exp(-lam s) Q(s)``, ``Q = sum_j f^(j) / lam^(j+1)``.

The peaks of ``|V|`` (the impact voltage) are the zeros of ``V'``. When ``E = 0``, ``V'`` is a
polynomial and its zeros are isolated in the Bernstein basis (``roots.py``). Otherwise
``V' = P' - lam E exp(-lam s)`` and ``g = exp(lam s) V' = exp(lam s) P' - lam E`` has
``g' = exp(lam s) k D'``: ``g`` is monotone between the zeros of ``D' = delta''`` (isolated in
the Bernstein basis), so each interval between them holds at most one zero of ``V'``, found
by bracketing. Nothing is stepped.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.dynamics import DU, DW, VOLT
from ..model.scalar import bracketed
from ..model.voltage import decay
from .propagation import ORDER, PRIMITIVE_TERMS, STATE_TERMS, THETA, powers, primitive_of_square
from .roots import crossings

#: ``lam = tau / (R C_p)`` above which the closed form is used (below it, the Taylor series).
LAM_SPLIT = THETA
_K = np.arange(STATE_TERMS, dtype=float)
_NOISE = 64 * float(np.finfo(float).eps)


def primitive_of_product(a: np.ndarray, b: np.ndarray, weight: float = 1.0) -> np.ndarray:
    """Coefficients of ``weight * int_0^s a b``, exact (``PRIMITIVE_TERMS`` of them)."""
    out = np.zeros(PRIMITIVE_TERMS)
    product = np.convolve(a, b)
    out[1:] = weight * product / np.arange(1, product.size + 1)
    return out


def _exp_moment(f: np.ndarray, lam: float) -> np.ndarray:
    """``Q = sum_j f^(j) / lam^(j+1)`` (power coefficients), so ``int_0^s f e^{-lam r} dr = Q(0) - e^{-lam s} Q(s)``."""
    q = np.empty_like(f)
    carry = 0.0
    for i in range(f.size - 1, -1, -1):
        carry = (f[i] + (i + 1) * carry) / lam
        q[i] = carry
    return q


def _derivative(a: np.ndarray) -> np.ndarray:
    """Power coefficients of ``a'``, padded to ``STATE_TERMS``."""
    out = np.zeros(STATE_TERMS)
    out[:-1] = a[1:] * _K[1:]
    return out


def _all_crossings(a: np.ndarray) -> list[float]:
    noise = _NOISE * float(np.abs(a).max()) if a.size else 0.0
    return sorted(set(crossings(a, +1, noise=noise) + crossings(a, -1, noise=noise)))


class Piece:
    """The voltage of the barrier in contact on one bracket, ``V(s) = P(s) + E exp(-lam s)``.

    Parameters
    ----------
    P : power coefficients (V), ``STATE_TERMS`` of them.
    E : V, amplitude of the free exponential (0 when ``V`` is a polynomial on the bracket).
    lam : ``tau / (R C_p)``.
    D : power coefficients of ``delta'`` (m/s) on the bracket.
    tau, R, chi : the bracket length (s), the load (Ohm) and the coupling (N/V).
    """

    __slots__ = ("P", "E", "lam", "D", "dP", "_dP_reversed", "harvested_poly", "converted_poly", "qP", "qD", "tau_R", "chi_tau")

    def __init__(self, P: np.ndarray, E: float, lam: float, D: np.ndarray, tau: float, R: float, chi: float):
        self.P, self.E, self.lam, self.D = P, E, lam, D
        self.dP = _derivative(P)
        self._dP_reversed = self.dP[::-1].tolist()
        self.tau_R, self.chi_tau = tau / R, chi * tau
        self.harvested_poly = primitive_of_square(P, self.tau_R)
        self.converted_poly = primitive_of_product(P, D, self.chi_tau)
        if E != 0.0:
            self.qP = _exp_moment(P, lam)
            self.qD = _exp_moment(D, lam)

    def value(self, s: float, pw: np.ndarray) -> float:
        """``V`` (V) at ``s``; ``pw`` are the powers of ``s`` (``propagation.powers``)."""
        v = float(pw[:STATE_TERMS] @ self.P)
        if self.E != 0.0:
            v += self.E * math.exp(-self.lam * s)
        return v

    def slope(self, s: float) -> float:
        """``dV/ds`` at ``s``."""
        v = 0.0
        for coefficient in self._dP_reversed:  # Horner
            v = v * s + coefficient
        if self.E != 0.0:
            v -= self.lam * self.E * math.exp(-self.lam * s)
        return v

    def harvested(self, s: float, pw: np.ndarray) -> float:
        """``int V^2 / R dt`` (J) from the bracket start to ``s``."""
        h = float(pw @ self.harvested_poly)
        if self.E != 0.0:
            e = math.exp(-self.lam * s)
            cross = self.qP[0] - e * float(pw[:STATE_TERMS] @ self.qP)
            square = -math.expm1(-2.0 * self.lam * s) / (2.0 * self.lam)
            h += self.tau_R * self.E * (2.0 * cross + self.E * square)
        return h

    def converted(self, s: float, pw: np.ndarray) -> float:
        """``int chi V delta' dt`` (J) from the bracket start to ``s``."""
        c = float(pw @ self.converted_poly)
        if self.E != 0.0:
            e = math.exp(-self.lam * s)
            c += self.chi_tau * self.E * (self.qD[0] - e * float(pw[:STATE_TERMS] @ self.qD))
        return c

    def peaks(self, limit: float = 1.0) -> list[float]:
        """Every ``s`` in ``(0, limit]`` where ``V' = 0``: the candidates for the peak ``|V|``."""
        if self.E == 0.0:
            return [s for s in _all_crossings(self.dP) if s <= limit]
        # g = exp(lam s) V' is monotone between the zeros of D' (see the module docstring).
        cuts = [0.0] + [z for z in _all_crossings(_derivative(self.D)) if 0.0 < z < 1.0] + [1.0]
        found = []
        f_lo = self.slope(0.0)
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            f_hi = self.slope(hi)
            if f_hi == 0.0:
                found.append(hi)
            elif f_lo != 0.0 and (f_lo < 0.0) != (f_hi < 0.0):
                found.append(bracketed(self.slope, lo, hi, xtol=1e-17))
            f_lo = f_hi
        return [s for s in found if s <= limit]


def driven(V0: float, D: np.ndarray, lam: float, k: float, tau: float, R: float, chi: float) -> Piece:
    """The one-way voltage on a bracket: ``dV/ds = -lam V + k D(s)`` from ``V(0) = V0``."""
    if lam <= LAM_SPLIT:
        # One more Taylor series, exact to rounding like the state (|lam| <= THETA).
        P = np.empty(STATE_TERMS)
        P[0] = V0
        for i in range(ORDER):
            P[i + 1] = (k * D[i] - lam * P[i]) / (i + 1)
        return Piece(P, 0.0, lam, D, tau, R, chi)
    # The polynomial particular solution: P' + lam P = k D, coefficient by coefficient from the
    # top, lam p_i + (i + 1) p_{i+1} = k d_i (stable: lam > THETA).
    P = np.empty(STATE_TERMS)
    carry = 0.0
    for i in range(ORDER, -1, -1):
        carry = (k * D[i] - (i + 1) * carry) / lam
        P[i] = carry
    return Piece(P, V0 - float(P[0]), lam, D, tau, R, chi)


class CircuitState:
    """The two patch circuits of a run (``voltage_model`` 1 and 2), exact event by event.

    Per barrier (index ``(side + 1) // 2``: left 0, right 1) it keeps the voltage ``V`` (V) booked
    at time ``t`` (s) and the energy harvested up to then (J); and the energy converted by the
    barriers so far (J), the peak ``|V|`` of the open contact (V), and the voltage of the barrier
    in contact on the open bracket (a :class:`Piece`, with its side).

    Parameters
    ----------
    chi : N/V, coupling; C_p : F, patch capacitance; R : Ohm, load.
    coupled : True under ``voltage_model = 2`` (``V`` is a column of the contact state).
    t0 : s, start time.
    """

    def __init__(self, chi: float, C_p: float, R: float, coupled: bool, t0: float):
        self.chi, self.C_p, self.R, self.coupled = chi, C_p, R, coupled
        self.RC = R * C_p
        self.V = [0.0, 0.0]
        self.t = [float(t0), float(t0)]
        self.harvested = [0.0, 0.0]
        self.converted = 0.0
        self.peak = 0.0
        self.piece: Piece | None = None
        self.piece_side = 0

    def open(self, c: np.ndarray, tau: float, side: int) -> Piece:
        """The voltage of the barrier on ``side`` over a contact bracket whose state has the Taylor
        coefficients ``c`` and which lasts ``tau`` s; it becomes the open piece."""
        D = side * (c[:, DW] - c[:, DU])  # delta' (m/s)
        if self.coupled:
            piece = Piece(c[:, VOLT].copy(), 0.0, tau / self.RC, D, tau, self.R, self.chi)
        else:
            piece = driven(self.V[(side + 1) // 2], D, tau / self.RC, tau * self.chi / self.C_p, tau, self.R, self.chi)
        self.piece, self.piece_side = piece, side
        return piece

    def close(self, s: float, pw: np.ndarray, t: float) -> None:
        """Book the voltage of the barrier in contact where the state stands: at ``s`` on the open
        bracket (``pw``: its powers), time ``t`` (s)."""
        piece = self.piece
        if piece is None:
            return
        i = (self.piece_side + 1) // 2
        v = piece.value(s, pw)
        self.V[i], self.t[i] = v, t
        self.harvested[i] += piece.harvested(s, pw)
        self.converted += piece.converted(s, pw)
        self.peak = max(self.peak, abs(v))
        self.piece = None

    def contact(self, side: int, t: float) -> None:
        """A contact with the barrier on ``side`` starts at ``t`` (s) from the voltage its circuit
        decayed to since it was booked."""
        i = (side + 1) // 2
        v, harvested = decay(self.V[i], t - self.t[i], self.RC, self.C_p)
        self.V[i], self.t[i] = v, t
        self.harvested[i] += harvested
        self.peak = abs(v)

    def peak_at(self, s: float) -> None:
        """A zero of ``V'`` at ``s`` on the open bracket: a candidate for the impact voltage."""
        self.peak = max(self.peak, abs(self.piece.value(s, powers(s))))

    def now(self, side: int, s: float, pw: np.ndarray, t: float) -> tuple[float, float]:
        """Voltage (V) of the barrier on ``side`` at time ``t`` (s), at ``s`` on the open bracket
        (``pw``: its powers), and its energy harvested so far (J)."""
        i = (side + 1) // 2
        if self.piece is not None and side == self.piece_side:
            return self.piece.value(s, pw), self.harvested[i] + self.piece.harvested(s, pw)
        v, harvested = decay(self.V[i], t - self.t[i], self.RC, self.C_p)
        return v, self.harvested[i] + harvested

    def converted_now(self, s: float, pw: np.ndarray) -> float:
        """The energy converted so far (J), the open bracket up to ``s`` included."""
        if self.piece is None:
            return self.converted
        return self.converted + self.piece.converted(s, pw)

    def to_dict(self) -> dict:
        """The booked state, JSON-safe (the open piece is rebuilt from the bracket)."""
        return {"V": list(self.V), "t": list(self.t), "harvested": list(self.harvested),
                "converted": self.converted, "peak": self.peak}

    def restore(self, data: dict) -> None:
        """Set the booked state saved by :meth:`to_dict`."""
        self.V = [float(v) for v in data["V"]]
        self.t = [float(t) for t in data["t"]]
        self.harvested = [float(h) for h in data["harvested"]]
        self.converted = float(data["converted"])
        self.peak = float(data["peak"])
