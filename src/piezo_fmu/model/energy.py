"""The energies of the damper and the rates of its energy flows (docs/model.md sections 3 and 5).

The mechanical energy is kinetic, plus the potential energy of the main spring ``K`` (stretched
by ``p - y``) and of the barrier in contact (``K_eq``, deflected by ``delta``). It changes by the
work of the base, the viscous dissipation in ``C`` and ``C_eq``, the plastic losses of the
switches (:func:`piezo_fmu.model.dynamics.capture` and ``release``) and, under the coupled circuit
model, the electrical work of the patch.
"""

from __future__ import annotations

import numpy as np

from .dynamics import DU, DW, FREE, U


def kinetic(M_main: float, m_impact: float, dp: float, dq: float) -> float:
    """Kinetic energy (J) of the main body (mass ``M_main``, kg) and the impact body (``m_impact``):
    ``M`` and ``m`` in free flight, ``M - M_eq`` and ``m + M_eq`` in contact."""
    return 0.5 * (M_main * dp**2 + m_impact * dq**2)


def spring(stiffness: float, stretch: float) -> float:
    """Potential energy (J) of a spring of ``stiffness`` (N/m) stretched by ``stretch`` (m)."""
    return 0.5 * stiffness * stretch**2


def deflection(side: int, d: float, p: float, q: float) -> float:
    """Tip deflection ``delta = side (q - p) - d/2`` (m) of the barrier on ``side`` (docs/model.md
    section 3); positive while the impact mass presses into it."""
    return side * (q - p) - d / 2


def energy_rates(side: int, K: float, C: float, n: int = 5) -> np.ndarray:
    """The rates behind the energy flows, as columns acting on the deviation state x = (u, w, u',
    w', 1[, V]): ``u'`` (the power dissipated in ``C`` is ``C u'^2``), ``delta'`` (that in ``C_eq``
    is ``C_eq delta'^2``; its sign does not matter; zero in free flight) and ``K u + C u'`` (minus
    the force on the base: the base's power is ``-v (K u + C u')``)."""
    R = np.zeros((n, 3))
    R[DU, 0] = 1.0
    if side != FREE:
        R[[DU, DW], 1] = [-1.0, 1.0]
    R[[U, DU], 2] = [K, C]
    return R
