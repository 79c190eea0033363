"""The equations of motion of the damper, phase by phase (docs/model.md sections 1-3).

Every phase is linear. In deviation coordinates from the base, ``u = p - y`` and ``w = q - y``,
the state ``x = (u, w, u', w', 1)`` obeys ``x' = A x`` with ``A`` fixed per phase (free flight,
or contact with the left or the right barrier); the constant 1 carries the contact offset
``d/2``. Under ``voltage_model = 2`` the contact state carries the patch voltage ``V`` as a sixth
entry. The forces depend only on ``p - y``, ``p' - v`` and ``q - p``, so the rows of ``A`` for
``u''`` and ``w''`` give the absolute accelerations ``p''`` and ``q''`` whatever the base does;
under a first-order hold of the base (``y'' = 0``) they are also ``u''`` and ``w''``, and
``x' = A x`` is the whole motion.

Also here: the event functions of each phase, as linear functionals of the state, and the
momentum-exact switch rules (docs/model.md section 3, decision "momentum-exact mass bookkeeping").
"""

from __future__ import annotations

import math

import numpy as np

#: The phases: free flight, contact with the right barrier (``q - p = +d/2``) or the left one.
FREE = 0
RIGHT = +1
LEFT = -1

#: Columns of the deviation state x = (u, w, u', w', 1), with u = p - y(t), w = q - y(t); in
#: contact under voltage_model = 2, the patch voltage V of the barrier in contact follows.
U, W, DU, DW, ONE, VOLT = range(6)


def free_matrix(M: float, K: float, C: float) -> np.ndarray:
    """Free flight on x = (u, w, u', w', 1): M u'' + C u' + K u = 0, w'' = 0 (eqs. 1-2)."""
    A = np.zeros((5, 5))
    A[U, DU] = A[W, DW] = 1.0
    A[DU, U] = -K / M
    A[DU, DU] = -C / M
    return A


def free_spectral_radius(M: float, K: float, C: float) -> float:
    """1/s: the largest ``|lambda|`` of ``M lambda^2 + C lambda + K = 0`` (the other eigenvalues
    of free flight are zero): ``sqrt(K / M)`` when underdamped, the faster decay rate otherwise."""
    a, b = C / (2.0 * M), K / M
    if a * a <= b:
        return math.sqrt(b)
    return a + math.sqrt(a * a - b)


def contact_matrix(M1: float, m1: float, K: float, C: float, K_eq: float, C_eq: float, d: float, side: int,
                   coupling: tuple[float, float, float] | None = None) -> np.ndarray:
    """Contact with the barrier on ``side`` (docs/model.md section 3, eqs. 3-6) on x = (u, w, u', w', 1).

    ``s F = K_eq (w - u) + C_eq (w' - u') - s K_eq d/2`` acts on the main body (mass
    ``M1 = M - M_eq``) and its opposite on the impact body (mass ``m1 = m + M_eq``). With
    ``coupling = (chi, C_p, R)`` (``voltage_model = 2``) the state is x = (u, w, u', w', 1, V): the
    patch voltage adds ``chi V`` to the contact force ``F`` and obeys ``C_p V' + V / R = chi delta'``
    (eqs. 20-21).
    """
    n = 5 if coupling is None else 6
    force = np.zeros(n)
    force[[U, W, DU, DW]] = [-K_eq, K_eq, -C_eq, C_eq]
    force[ONE] = -side * K_eq * d / 2
    A = np.zeros((n, n))
    if coupling is not None:
        chi, C_p, R = coupling
        force[VOLT] = side * chi
        A[VOLT, [DU, DW]] = [-side * chi / C_p, side * chi / C_p]
        A[VOLT, VOLT] = -1.0 / (R * C_p)
    A[U, DU] = A[W, DW] = 1.0
    with np.errstate(over="ignore", invalid="ignore"):  # beyond double range: the integrator refuses it
        A[DU] = force / M1
        A[DU, U] -= K / M1
        A[DU, DU] -= C / M1
        A[DW] = -force / m1
    return A


def mirror_signs(n: int) -> np.ndarray:
    """``S`` with ``A_left = S A_right S`` (:func:`contact_matrix`): the constant (and the voltage)
    change sign, the displacements and velocities do not."""
    signs = np.ones(n)
    signs[ONE:] = -1.0
    return signs


def event_functionals(side: int, d: float, n: int = 5) -> np.ndarray:
    """Event functions of a phase as columns acting on x = (u, w, u', w', 1) (and V, n = 6).

    Free flight: ``r - d/2``, ``-r - d/2`` (contact onsets, right and left; ``r = q - p``) and ``p'``
    (its falling zeros are the maxima of ``p``, eq. 29); contact on ``side``: ``delta`` (its falling
    zero is the separation), ``delta'`` (its falling zero is the peak deflection, which gives
    ``V_i``) and ``p'``. The base velocity in ``p' = u' + v`` is to be added by the caller.
    """
    L = np.zeros((n, 3))
    if side == FREE:
        L[[U, W], 0] = [-1.0, 1.0]
        L[[U, W], 1] = [1.0, -1.0]
        L[ONE, :2] = -d / 2
    else:
        L[[U, W], 0] = [-side, side]
        L[ONE, 0] = -d / 2
        L[[DU, DW], 1] = [-side, side]
    L[DU, 2] = 1.0
    return L


def capture(m: float, M_eq: float, dp: float, dq: float) -> tuple[float, float]:
    """Contact onset: the impact mass ``m`` captures the barrier's tip mass ``M_eq``, which moved
    with the main mass, plastically. Returns ``q'`` just after (m/s) and the energy lost (J);
    the main body keeps ``p'``."""
    dq_after = (m * dq + M_eq * dp) / (m + M_eq)
    loss = 0.5 * m * M_eq / (m + M_eq) * (dq - dp) ** 2
    return dq_after, loss


def release(M: float, M1: float, M_eq: float, dp: float, dq: float) -> tuple[float, float]:
    """Separation: the tip mass ``M_eq``, which moved with the impact mass, rejoins the main body
    (mass ``M1 = M - M_eq`` in contact) plastically. Returns ``p'`` just after (m/s) and the energy
    lost (J); the impact mass leaves with ``q'``."""
    dp_after = (M1 * dp + M_eq * dq) / M
    loss = 0.5 * M1 * M_eq / M * (dp - dq) ** 2
    return dp_after, loss


def approach_sign(K: float, C: float, u: float, du: float, side: int) -> int:
    """Sign of the relative acceleration of the impact mass towards the barrier on ``side`` from
    the main spring and damper alone (the barrier's force left out), at ``u = p - y`` (m) and
    ``u' = p' - v`` (m/s): it decides whether a body at rest on a barrier presses into it."""
    towards = side * (K * u + C * du)  # -side * main acceleration
    return (towards > 0.0) - (towards < 0.0)
