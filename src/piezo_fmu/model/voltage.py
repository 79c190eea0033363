"""The patch voltage (docs/model.md section 5, eqs. 20-28).

Three models (``voltage_model``):

- 0, quasi-static (the paper's eqs. 25-28): ``V = k_V delta``, an open-circuit voltage of the
  barrier in contact, zero out of contact; nothing is harvested;
- 1, circuit, one-way (eqs. 20-21): the patch is a capacitance ``C_p`` across the load ``R``,
  driven by the deflection rate of its barrier, ``C_p V' + V / R = chi delta'``, without acting
  back on the barrier; between contacts ``delta' = 0`` and ``V`` decays through the load;
- 2, circuit, coupled: as 1, plus the force ``chi V`` on the barrier in contact (a column of the
  contact matrix, :func:`piezo_fmu.model.dynamics.contact_matrix`).
"""

from __future__ import annotations

import math

#: ``voltage_model`` values: the paper's quasi-static voltage ``V = k_V delta``; the patch
#: capacitance and load as a circuit driven one way by the barrier (eqs. 20-21); the same circuit
#: with ``chi V`` acting back on the barrier in contact.
QUASI_STATIC = 0
CIRCUIT = 1
COUPLED = 2


def quasi_static(k_V: float, delta: float) -> float:
    """Open-circuit patch voltage (V) at tip deflection ``delta`` (m), ``k_V`` in V/m (eqs. 25-28)."""
    return k_V * delta


def circuit_rate(V: float, delta_rate: float, chi: float, C_p: float, R: float) -> float:
    """``V'`` (V/s) of the patch across its load: ``C_p V' + V / R = chi delta'`` (eqs. 20-21), with
    ``delta'`` (m/s) the deflection rate of its barrier (0 out of contact)."""
    return (chi * delta_rate - V / R) / C_p


def decay(V0: float, dt: float, RC: float, C_p: float) -> tuple[float, float]:
    """Voltage (V) after ``dt`` s of free decay from ``V0`` through the load (time constant ``RC``,
    s), and the energy (J) harvested meanwhile: the closed-form solution of the circuit out of
    contact."""
    if dt == 0.0 or V0 == 0.0:
        return V0, 0.0
    return V0 * math.exp(-dt / RC), -0.5 * C_p * V0 * V0 * math.expm1(-2.0 * dt / RC)
