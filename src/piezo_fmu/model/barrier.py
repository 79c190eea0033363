"""The barrier: a clamped-free steel beam with one piezoelectric patch (docs/model.md section 4-5).

Derives the tip-referred equivalents ``M_eq`` and ``K_eq`` (eqs. 22-23) from the first
cantilever mode, the quasi-static voltage gain ``k_V`` (eqs. 25-27, with the patch-average
curvature of docs/model.md section 5), and the patch as a circuit element: its capacitance ``C_p`` and
electromechanical coupling ``chi`` (eqs. 20-21).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .scalar import bracketed

#: ``barrier_mode`` values: derive ``M_eq``/``K_eq`` from the beam geometry, or take them as given.
DERIVED = 0
EXPLICIT = 1
#: The equivalent mass and stiffness printed in the paper (kg, N/m); see docs/model.md section 9,
#: departures from the paper: they cannot be derived from Table 1.
PRINTED_M_EQ = 0.0292
PRINTED_K_EQ = 46.7753e6

#: Normalisation of the first mode, chosen so that phi_1(L) = 1 (docs/model.md section 4).
C1 = 0.5


@lru_cache(maxsize=1)
def first_mode_root() -> float:
    """``beta_1 L``: the first root of ``cos(x) cosh(x) + 1 = 0`` (dimensionless)."""
    return bracketed(lambda x: math.cos(x) * math.cosh(x) + 1.0, 1.5, 2.5)


@lru_cache(maxsize=1)
def first_mode_kappa() -> float:
    """``kappa_1 = (sinh bL - sin bL) / (cosh bL + cos bL)`` (eq. 18, dimensionless)."""
    bl = first_mode_root()
    return (math.sinh(bl) - math.sin(bl)) / (math.cosh(bl) + math.cos(bl))


def mode_shape(x, L: float):
    """First cantilever mode ``phi_1(x)`` (eq. 17), with ``phi_1(L) = 1``."""
    b = first_mode_root() / L
    k = first_mode_kappa()
    bx = b * np.asarray(x, dtype=float)
    return C1 * (np.cosh(bx) - np.cos(bx) - k * (np.sinh(bx) - np.sin(bx)))


def mode_slope(x, L: float):
    """``phi_1'(x)`` in 1/m."""
    b = first_mode_root() / L
    k = first_mode_kappa()
    bx = b * np.asarray(x, dtype=float)
    return C1 * b * (np.sinh(bx) + np.sin(bx) - k * (np.cosh(bx) - np.cos(bx)))


@lru_cache(maxsize=1)
def _gauss_legendre() -> tuple[np.ndarray, np.ndarray]:
    return np.polynomial.legendre.leggauss(40)


def integral_phi_squared(a: float, b: float, L: float) -> float:
    """``int_a^b phi_1(x)^2 dx`` in m, by 40-point Gauss-Legendre (exact to rounding here)."""
    if b <= a:
        return 0.0
    nodes, weights = _gauss_legendre()
    x = 0.5 * (b - a) * nodes + 0.5 * (b + a)
    return float(0.5 * (b - a) * np.dot(weights, mode_shape(x, L) ** 2))


@lru_cache(maxsize=8)
def _eta1(L: float) -> float:
    """``eta_1 = int_0^L phi_1^2 dx`` (eq. 19), m: a function of ``L`` alone, so sweeps over the
    patch and the masses compute it once."""
    return integral_phi_squared(0.0, L, L)


@dataclass(frozen=True)
class Barrier:
    """Equivalent tip quantities of one barrier, SI.

    Attributes
    ----------
    M_eq : kg, equivalent tip mass (eq. 22).
    K_eq : N/m, equivalent tip stiffness (eq. 23).
    k_V : V/m, quasi-static patch voltage per metre of tip deflection.
    beta1 : 1/m, first-mode wavenumber.
    kappa1 : first-mode coefficient (eq. 18).
    eta1 : m, ``int_0^L phi_1^2 dx`` (eq. 19).
    phi2_patch : m, ``int_{x1}^{x2} phi_1^2 dx``.
    EI_b, EI_p : N m^2, bending stiffness of the beam and of the patch (eqs. 13-14).
    z_n : m, neutral-axis offset from the beam mid-plane in the patch region.
    y_p : m, distance from the neutral axis to the patch mid-plane.
    kappa_bar : 1/m^2, patch-average curvature per metre of tip deflection.
    omega : rad/s, first natural frequency of the barrier, ``sqrt(K_eq / M_eq)``.
    explicit : True when ``M_eq`` and ``K_eq`` were given rather than derived.
    C_p : F, capacitance of the patch, ``eps33 W_p L_p / t_p``.
    e31 : C/m^2 (N/(V m)), ``|d31| E_p``.
    chi : N/V (C/m), coupling per unit tip deflection,
        ``e31 W_p y_p |phi_1'(x2) - phi_1'(x1)| / phi_1(L)``: ``C_p V' + V / R = chi delta'``.
    """

    M_eq: float
    K_eq: float
    k_V: float
    beta1: float
    kappa1: float
    eta1: float
    phi2_patch: float
    EI_b: float
    EI_p: float
    z_n: float
    y_p: float
    kappa_bar: float
    omega: float
    explicit: bool
    C_p: float = 0.0
    e31: float = 0.0
    chi: float = 0.0


def derive_barrier(params) -> Barrier:
    """Barrier equivalents of ``params`` (a :class:`~piezo_fmu.model.parameters.Parameters`, or any
    object with its beam, patch and barrier-mode attributes).

    With ``barrier_mode = 0`` (default) ``M_eq`` and ``K_eq`` follow from the geometry by
    eqs. 22-23; with ``barrier_mode = 1`` the given ``params.M_eq`` and ``params.K_eq`` pass
    through unchanged. The voltage gain ``k_V`` always follows from the geometry.
    """
    L = params.L
    beta1 = first_mode_root() / L
    eta1 = _eta1(L)
    x2 = params.x1 + params.L_p
    phi2_patch = integral_phi_squared(params.x1, x2, L)

    EI_b = params.E_b * params.W_b * params.t_b**3 / 12.0
    # docs/model.md, decision (neutral axis): the true offset, half of the printed eq. 15.
    z_n = params.E_p * params.t_p * (params.t_b + params.t_p) / (2.0 * (params.E_b * params.t_b + params.E_p * params.t_p))
    EI_p = params.E_p * params.W_p * params.t_p / 12.0 * (params.t_p**2 + 3.0 * (params.t_p + params.t_b - 2.0 * z_n) ** 2)

    if params.barrier_mode == EXPLICIT:
        M_eq, K_eq = params.M_eq, params.K_eq
    else:
        M_eq = params.rho_b * params.t_b * params.W_b * eta1 + params.rho_p * params.t_p * params.W_p * phi2_patch
        K_eq = EI_b * eta1 * beta1**4 + EI_p * beta1**4 * phi2_patch

    # docs/model.md, decision (where the strain is read): patch-average curvature per unit tip deflection.
    phi_L = float(mode_shape(L, L))
    slope_change = float(mode_slope(x2, L) - mode_slope(params.x1, L))
    kappa_bar = slope_change / (params.L_p * phi_L)
    y_p = (params.t_b + params.t_p) / 2.0 - z_n
    k_V = params.g31 * params.E_p * params.L_p * y_p * abs(kappa_bar)
    # The circuit (eqs. 20-21; docs/model.md section 5, decision "the electrode gap"): magnitudes, so
    # that the voltage of the barrier in contact is positive while its deflection grows.
    C_p = params.eps33 * params.W_p * params.L_p / params.t_p
    e31 = abs(params.d31) * params.E_p
    chi = e31 * params.W_p * y_p * abs(slope_change) / phi_L

    return Barrier(
        M_eq=M_eq, K_eq=K_eq, k_V=k_V, beta1=beta1, kappa1=first_mode_kappa(), eta1=eta1,
        phi2_patch=phi2_patch, EI_b=EI_b, EI_p=EI_p, z_n=z_n, y_p=y_p, kappa_bar=kappa_bar,
        omega=math.sqrt(K_eq / M_eq), explicit=params.barrier_mode == EXPLICIT,
        C_p=C_p, e31=e31, chi=chi,
    )
