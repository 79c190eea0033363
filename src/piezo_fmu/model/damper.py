"""The damper of one parameter set: everything the equations of motion need, derived once.

:class:`Damper` is the model as the solver and the FMI interfaces see it, in the manner of the
FMI reference models' ``model.c``: the phase matrices, the event functions, the switch rules and
the energies of one damper, with no integration scheme in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import dynamics, energy
from .barrier import Barrier, derive_barrier
from .dynamics import FREE, LEFT, RIGHT
from .parameters import Parameters
from .voltage import COUPLED


@dataclass(frozen=True, eq=False)
class Damper:
    """The piezo-impact damper of ``params`` (SI).

    Attributes
    ----------
    params : the parameters.
    barrier : the barrier equivalents (eqs. 11-23) and the patch constants.
    M_contact, m_contact : kg, the masses of the main body and of the impact body in contact,
        ``M - M_eq`` and ``m + M_eq`` (docs/model.md section 3).
    free, contact : the state matrices of free flight and of contact with the right barrier
        (:mod:`piezo_fmu.model.dynamics`); read-only.
    free_rho : 1/s, the spectral radius of ``free``.
    coupled : True under ``voltage_model = 2``, where the contact state carries ``V``.
    """

    params: Parameters
    barrier: Barrier
    M_contact: float
    m_contact: float
    free: np.ndarray
    contact: np.ndarray
    free_rho: float
    coupled: bool

    @classmethod
    def of(cls, params: Parameters) -> "Damper":
        barrier = derive_barrier(params)
        M, m, K, C = params.M, params.m, params.K, params.C
        M_contact, m_contact = M - barrier.M_eq, m + barrier.M_eq
        coupled = params.voltage_model == COUPLED
        coupling = (barrier.chi, barrier.C_p, params.R_load) if coupled else None
        free = dynamics.free_matrix(M, K, C)
        contact = dynamics.contact_matrix(M_contact, m_contact, K, C, barrier.K_eq, params.C_eq, params.d, RIGHT,
                                          coupling)
        free.flags.writeable = contact.flags.writeable = False
        return cls(params, barrier, M_contact, m_contact, free, contact,
                   dynamics.free_spectral_radius(M, K, C), coupled)

    @property
    def contact_size(self) -> int:
        """Entries of the contact state: 5, or 6 with the voltage under ``voltage_model = 2``."""
        return self.contact.shape[0]

    def matrix(self, side: int) -> np.ndarray:
        """The state matrix of phase ``side``; the left barrier's is the right one's seen with
        the signs of the constant (and the voltage) turned over, exactly."""
        if side == FREE:
            return self.free
        if side == RIGHT:
            return self.contact
        signs = dynamics.mirror_signs(self.contact_size)
        return self.contact * np.outer(signs, signs)

    def functionals(self, side: int) -> np.ndarray:
        """The event functions of phase ``side`` (:func:`piezo_fmu.model.dynamics.event_functionals`)."""
        return dynamics.event_functionals(side, self.params.d, 5 if side == FREE else self.contact_size)

    def rates(self, side: int) -> np.ndarray:
        """The energy-flow rates of phase ``side`` (:func:`piezo_fmu.model.energy.energy_rates`)."""
        return energy.energy_rates(side, self.params.K, self.params.C, 5 if side == FREE else self.contact_size)

    def masses(self, side: int) -> tuple[float, float]:
        """The masses (kg) of the main body and of the impact body in phase ``side``."""
        if side == FREE:
            return self.params.M, self.params.m
        return self.M_contact, self.m_contact

    def capture(self, dp: float, dq: float) -> tuple[float, float]:
        """Contact onset at velocities ``dp``, ``dq`` (m/s): ``q'`` after (m/s) and the plastic loss (J)."""
        return dynamics.capture(self.params.m, self.barrier.M_eq, dp, dq)

    def release(self, dp: float, dq: float) -> tuple[float, float]:
        """Separation at velocities ``dp``, ``dq`` (m/s): ``p'`` after (m/s) and the plastic loss (J)."""
        return dynamics.release(self.params.M, self.M_contact, self.barrier.M_eq, dp, dq)

    def deflection(self, side: int, p: float, q: float) -> float:
        """Tip deflection (m) of the barrier on ``side`` at displacements ``p``, ``q`` (m); negative
        when the impact mass is off it."""
        return energy.deflection(side, self.params.d, p, q)

    def mechanical_energy(self, side: int, p: float, dp: float, q: float, dq: float, y: float) -> tuple[float, float, float]:
        """Kinetic energy, and the potential energies of ``K`` and of the barrier in contact (J),
        in phase ``side`` with the base at ``y`` (m)."""
        params = self.params
        if side == FREE:
            return energy.kinetic(params.M, params.m, dp, dq), energy.spring(params.K, p - y), 0.0
        return (energy.kinetic(self.M_contact, self.m_contact, dp, dq), energy.spring(params.K, p - y),
                energy.spring(self.barrier.K_eq, energy.deflection(side, params.d, p, q)))

    @property
    def contact_frequency(self) -> float:
        """rad/s: undamped angular frequency ``sqrt(K_eq / mu)`` of the relative motion in contact
        (short-circuited patch), ``mu`` the reduced mass of ``M - M_eq`` and ``m + M_eq``."""
        mu = self.M_contact * self.m_contact / (self.M_contact + self.m_contact)
        return math.sqrt(self.barrier.K_eq / mu)


__all__ = ["Damper", "FREE", "LEFT", "RIGHT"]
