"""What the batch engine needs of one damper: the two phases in closed form, the bounds that make
event location rigorous, and the switch rules' masses (docs/model.md sections 2-3).

Relative to a base moving as a ramp (one hold step, :mod:`.drive`), ``u = p - y`` and ``w = q - y``,
every phase is linear and unforced:

- **Free flight.** ``u'' + 2 a u' + w_n^2 u = 0`` (``a = C / 2M``, ``w_n^2 = K / M``) and ``w'' = 0``:
  ``u(t) = e^{-a t} [c(t) u0 + s(t) (a u0 + u0')]``, ``u'(t) = e^{-a t} [c(t) u0' - s(t) (w_n^2 u0 + a u0')]``
  with ``c = cos(w_d t)``, ``s = sin(w_d t) / w_d`` (underdamped; ``cosh`` and ``sinh`` of ``b t``,
  ``b = sqrt(a^2 - w_n^2)``, overdamped, the series at critical damping), and ``w = w0 + w0' t``.
  Overdamped, beyond ``a t =`` :data:`DECAYS_APART`, ``e^{-a t} cosh(b t)`` and
  ``e^{-a t} sinh(b t) / b`` are taken as the two decays they are, ``e^{-(a - b) t} (1 + e^{-2 b t}) / 2``
  and ``e^{-(a - b) t} (1 - e^{-2 b t}) / 2b`` with ``a - b = w_n^2 / (a + b)``: ``cosh`` alone would
  overflow once ``b t`` passes 710 (a main mass damped heavily, or a hold step long against ``M / C``). The impact mass's distance from a barrier,
  ``g = +-(w - u) - d/2``, has ``|g''| = |u''| <= (w_n + 2a) sqrt(u'^2 + w_n^2 u^2)``, and that root
  is non-increasing in free flight (``d/dt (u'^2 + w_n^2 u^2) = -4 a u'^2``): a bound that holds
  from any instant on.
- **Contact with the barrier on side** ``s`` (+1 right, -1 left). At rest in contact the main spring
  is unstretched and the barrier undeflected, so the state relative to that rest,
  ``e = (u, w - s d/2, u', w'[, s V])`` (the patch voltage ``V`` only under ``voltage_model = 2``),
  obeys ``e' = B e`` with the same ``B`` on both sides: the left barrier is the right one mirrored
  (:func:`piezo_fmu.model.dynamics.mirror_signs`). ``B`` is diagonalised once,
  ``B = Q diag(lam) Q^-1`` (balanced first, so that metres, metres per second and volts do not
  spoil the eigenvectors' conditioning), and ``e(t) = Re(Q (alpha * exp(lam t)))`` with the modal
  amplitudes ``alpha = Q^-1 e0``. The deflection ``delta = s (e_w - e_u)`` and its rate are sums of
  modes, and ``|delta''(t)| <= sum_j |g_j alpha_j| |lam_j|^2 exp(Re lam_j t)``, non-increasing too
  (no mode grows: the contact is passive). A mode no damping reaches (``C = C_eq = 0``, or ``C = 0``
  for the slow mode, which ``C_eq`` damps by a part in 1e16 or so) may come out of the
  diagonalisation with a real part of rounding's size, either sign; one that is positive, and within
  :data:`ROUNDING` of the spectral radius, is taken as 0: the mode keeps its size. The modal form
  is taken only where it is exact to about 1e-8 of the state (:data:`MAX_CONDITION`): eigenvectors
  of condition below 1e8 (no two modes coinciding), no two modes nearer than 1e-8 of the fastest
  (rounding of the fastest puts that much error into the slow ones: an impact mass of 1e16 kg), and
  the form within :data:`MAX_DEPARTURE` of ``expm(B t)`` over ten radians of the fastest mode (a
  component the balancing scales beyond rounding drops out of the modes: a barrier of 1e-30 N/m).
  Anything else is refused (:mod:`.limits` finds the range of the values that moved it there).

Both bounds make event location rigorous (:mod:`.kernel.location`): a step shorter than the bound
allows cannot jump over a contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, matrix_balance

from ...model.damper import Damper
from ...model.dynamics import DU, DW, ONE, RIGHT, U, VOLT, W
from ...model.parameters import Parameters
from ...model.rounding import EPS, NOISE_ULPS

#: Condition number of the contact phase's (balanced) eigenvectors beyond which it counts as
#: defective: the closed form would lose more than about 1e-8 of the state to rounding. Its inverse
#: bounds the modes' separation relative to the fastest, and the form's departure from the flow.
MAX_CONDITION = 1e8
#: How far the modal form may depart from the flow ``expm(B t)``, relative to the state: its rounding
#: stays near 1e-8 where the modes are at least ``1 / MAX_CONDITION`` apart; beyond this bound a
#: component of the state has dropped out of the modes (a barrier of 1e-29 N/m: a departure of 1).
MAX_DEPARTURE = 1e-6
#: ``a t`` (``a = C / 2M``) up to which overdamped free flight is ``e^{-a t} cosh(b t)`` as it stands
#: (``b < a``: no overflow); beyond, its two decays apart, which hold at any ``a t``.
DECAYS_APART = 700.0
#: The largest positive real part of a contact mode taken as 0, relative to the spectral radius: the
#: rounding level of an event function (an undamped mode comes out of ``eig`` within about 1 ulp).
ROUNDING = NOISE_ULPS * EPS


@dataclass(frozen=True, eq=False)
class FreeFlow:
    """Free flight of the main mass relative to a ramping base (see the module's text)."""

    a: float      # 1/s, C / 2M
    w2: float     # 1/s^2, K / M
    beta2: float  # 1/s^2, a^2 - w_n^2: < 0 underdamped

    @classmethod
    def of(cls, M: float, K: float, C: float) -> "FreeFlow":
        a = C / (2.0 * M)
        return cls(a, K / M, a * a - K / M)

    @property
    def bound_rate(self) -> float:
        """``w_n + 2a`` (1/s): ``|u''| <= bound_rate * sqrt(u'^2 + w_n^2 u^2)``."""
        return math.sqrt(self.w2) + 2.0 * self.a

    def coefficients(self, t) -> tuple:
        """``(e^{-a t} c(t), e^{-a t} s(t))`` for the times ``t`` (s), to apply with :meth:`apply`."""
        beta2 = self.beta2
        if abs(beta2) <= 1e-12 * self.w2:  # critical damping, to rounding
            bt2 = beta2 * t * t
            c, s = 1.0 + bt2 / 2.0, t * (1.0 + bt2 / 6.0)
        elif beta2 < 0.0:
            wd = math.sqrt(-beta2)
            c, s = np.cos(wd * t), np.sin(wd * t) / wd
        else:
            b = math.sqrt(beta2)
            near = self.a * np.asarray(t) <= DECAYS_APART
            if not np.all(near):  # the slow and the fast decay apart (see the module's text)
                t_far = np.where(near, 0.0, t)
                slow, apart = np.exp(-self.w2 / (self.a + b) * t_far), -np.expm1(-2.0 * b * t_far)
                far_c, far_s = slow * (1.0 - 0.5 * apart), slow * apart / (2.0 * b)
                near_c, near_s = self.coefficients(np.where(near, t, 0.0))
                return np.where(near, near_c, far_c), np.where(near, near_s, far_s)
            c, s = np.cosh(b * t), np.sinh(b * t) / b
        decay = np.exp(-self.a * t)
        return decay * c, decay * s

    def apply(self, coefficients: tuple, u, du) -> tuple:
        """``(u(t), u'(t))`` from ``(u0, u0')`` (m, m/s) with :meth:`coefficients` of ``t``."""
        ec, es = coefficients
        a, w2 = self.a, self.w2
        return ec * u + es * (a * u + du), ec * du - es * (w2 * u + a * du)


@dataclass(frozen=True, eq=False)
class ContactFlow:
    """Contact with either barrier in modal form (see the module's text); host numpy arrays."""

    lam: np.ndarray      # (n,) complex eigenvalues, 1/s, every real part <= 0
    Q: np.ndarray        # (n, n) complex eigenvectors (columns), physical units
    Q_inv: np.ndarray    # (n, n) complex
    gain: np.ndarray     # (n,) complex: delta = s Re(sum_j gain_j alpha_j exp(lam_j t))
    size: int            # 4, or 5 with the voltage

    @classmethod
    def of(cls, damper: Damper) -> "ContactFlow":
        A = damper.matrix(RIGHT)
        keep = [U, W, DU, DW] + ([VOLT] if damper.coupled else [])
        B = A[np.ix_(keep, keep)]
        rest = np.zeros(A.shape[0])
        rest[W], rest[ONE] = damper.params.d / 2.0, 1.0
        with np.errstate(all="ignore"):  # a contact beyond double range is refused below
            if np.any(np.abs(A @ rest) > 1e-12 * np.abs(A).max() * rest.sum()):
                raise AssertionError("contact: the rest state is not u = 0, w = d/2 (the model changed?)")
            lam, P, scale = _balanced_modes(B)
            condition = float(np.linalg.cond(P)) if np.isfinite(P).all() else math.inf
            apart = _separation(lam)
            modes = np.where(lam.real > 0.0, 1j * lam.imag, lam)
            Q = P * scale[:, None]
            Q_inv = np.linalg.inv(P) / scale[None, :] if condition < math.inf else P
            departure = _departure(B, modes, Q, Q_inv)
        params = damper.params
        if not (condition < MAX_CONDITION and apart * MAX_CONDITION >= 1.0 and departure <= MAX_DEPARTURE
                and np.all(lam.real <= ROUNDING * np.abs(lam).max())):
            raise ValueError(f"C_eq = {params.C_eq!r} N.s/m, m = {params.m!r} kg, M = {params.M!r} kg, "
                             f"C = {params.C!r} N.s/m (and the barrier's K_eq, M_eq): the contact phase is "
                             f"defective, inexact or grows (eigenvector condition {condition:.3g}, its closest "
                             f"modes {apart:.3g} of the fastest apart, its closed form {departure:.3g} of the state "
                             f"off the flow, eigenvalues {np.round(lam, 6).tolist()}); the batch engine's closed "
                             f"form needs distinct modes, none growing (allowed: condition below "
                             f"{MAX_CONDITION:g}, modes at least {1.0 / MAX_CONDITION:g} of the fastest apart, the "
                             f"flow within {MAX_DEPARTURE:g} of the state); the scalar core and the FMUs take this "
                             "damper")
        row = np.zeros(len(keep))
        row[0], row[1] = -1.0, 1.0
        return cls(modes, Q, Q_inv, row @ Q, len(keep))


def _balanced_modes(B: np.ndarray) -> tuple:
    """``(lam, P, scale)``: the eigenvalues and eigenvectors of ``B`` balanced by ``T = diag(scale)``
    (``T^-1 B T = P diag(lam) P^-1``); NaN where ``B``, or its balancing, leaves double range."""
    nan = (np.full(len(B), np.nan + 0j), np.full(B.shape, np.nan + 0j), np.ones(len(B)))
    if not np.isfinite(B).all():
        return nan
    _, (scale, _) = matrix_balance(B, permute=False, separate=True)
    balanced = (B * scale[None, :]) / scale[:, None]
    if not (np.isfinite(balanced).all() and np.isfinite(scale).all()):
        return nan
    lam, P = np.linalg.eig(balanced)
    return lam, P, scale


def _departure(B: np.ndarray, lam: np.ndarray, Q: np.ndarray, Q_inv: np.ndarray) -> float:
    """How far the modal form ``Q diag(exp(lam t)) Q^-1`` lies from the flow ``expm(B t)`` after one
    and ten radians of the fastest mode, relative to the state (NaN for NaN modes): positions in
    metres, velocities in metres a radian of the fastest mode, the voltage in the deflection that
    makes it. Balancing makes the modes' eigenvectors accurate in its own units; where it must scale
    one of the state's components by a factor beyond rounding (a barrier of no stiffness: 1e-100
    N/m), that component is lost from the modes, and the closed form leaves the flow."""
    fastest = float(np.abs(lam).max())
    if not np.isfinite(Q_inv).all() or not math.isfinite(fastest) or fastest == 0.0:
        return math.nan
    units = np.array([1.0, 1.0, fastest, fastest, abs(B[-1, 3]) or 1.0])[:len(B)]
    worst = 0.0
    for t in (1.0 / fastest, 10.0 / fastest):
        flow = expm(B * t)
        modal = ((Q * np.exp(lam * t)[None, :]) @ Q_inv).real
        scaled = lambda F: F * units[None, :] / units[:, None]  # noqa: E731  D^-1 F D
        worst = max(worst, float(np.abs(scaled(modal - flow)).max() / max(1.0, np.abs(scaled(flow)).max())))
    return worst


def _separation(lam: np.ndarray) -> float:
    """The distance between the two closest of the modes ``lam``, relative to the fastest (NaN for
    NaN modes): the eigenvalues are found within rounding of the fastest (``EPS |lam|_max``), so two
    modes nearer than ``1 / MAX_CONDITION`` of it have eigenvectors and rates correct to no more than
    about 1e-8 (a slow pair against a fast one: an impact mass of 1e12 kg on a barrier's tip of 4 g)."""
    gaps = np.abs(lam[:, None] - lam[None, :]) + np.diag(np.full(len(lam), np.inf))
    return float(gaps.min() / np.abs(lam).max())


@dataclass(frozen=True, eq=False)
class BatchModel:
    """What the batch engine needs of one damper (SI): the two flows and the switch rules'
    masses (``docs/model.md`` section 3)."""

    params: Parameters
    free: FreeFlow
    contact: ContactFlow
    half_gap: float   # m, d / 2
    M: float
    M1: float         # M - M_eq, kg: the main body in contact
    m: float
    M_eq: float
    K: float
    C: float
    coupled: bool
    tau_e: float      # s, R C_p: the decay time of a patch's voltage between contacts (inf when its voltage
    #                   does not act back, voltage_model 0 and 1: the engine carries none, and R C_p may be 0)
    K_eq: float       # N/m, the barrier's equivalent stiffness
    C_eq: float       # N.s/m, the barrier's damping
    C_p: float        # F, a patch's capacitance

    @classmethod
    def of(cls, params: Parameters) -> "BatchModel":
        damper = Damper.of(params)
        barrier = damper.barrier
        return cls(params, FreeFlow.of(params.M, params.K, params.C), ContactFlow.of(damper), params.d / 2.0,
                   params.M, damper.M_contact, params.m, barrier.M_eq, params.K, params.C, damper.coupled,
                   params.R_load * barrier.C_p if damper.coupled else math.inf, barrier.K_eq, params.C_eq,
                   barrier.C_p)
