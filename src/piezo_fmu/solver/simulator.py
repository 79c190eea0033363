"""The damper as a host reads it: :class:`Simulator`, the integrator with its readings.

:class:`~piezo_fmu.solver.integrator.Integrator` advances the state; a :class:`Simulator` adds
what hosts read (state, deflections, voltages, powers, the base force, the logs of impacts and
maxima, the metrics and the energy ledger) and saving and restoring the full state.
"""

from __future__ import annotations

import math

from ..model.dynamics import FREE, LEFT, RIGHT
from ..model.parameters import Parameters
from ..model.voltage import quasi_static
from .integrator import Integrator
from .ledger import EnergyLedger, ledger_totals
from .metrics import Metrics
from .records import Impact, State
from .snapshot import restore_into, snapshot_of


#: The names of :meth:`Simulator.readings`, in the order of :meth:`Simulator.reading_values`.
READINGS = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity", "deflection_left",
            "deflection_right", "voltage_left", "voltage_right", "base_force", "impact_count", "last_impact_voltage",
            "voltage_rms", "average_power", "damping_inclination", "energy_dissipated", "energy_balance_error",
            "harvested_energy", "power_left", "power_right", "harvested_energy_left", "harvested_energy_right",
            "damping_inclination_ls")
#: The readings of the energy ledger's quadratures: an instant at which a host reads none of them
#: is spared their cost (:meth:`Simulator.reading_values` with ``energy=False``).
ENERGY_READINGS = ("energy_dissipated", "energy_balance_error", "harvested_energy", "harvested_energy_left",
                   "harvested_energy_right")


class Simulator(Integrator):
    """The damper from ``t0`` on, advanced by :meth:`advance` with any chop of time, and read.

    Parameters
    ----------
    params : Parameters
        The damper, SI.
    y0, v0 : float
        Base displacement (m) and velocity (m/s) at ``t0``.
    t0 : float
        Start time, s.
    log_limit : int or None
        Most impacts and maxima kept in :attr:`impacts` and :attr:`maxima` (the oldest are
        dropped); the metrics never depend on it. None keeps all.
    """

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> State:
        return State(self.t, self._p, self._dp, self._q, self._dq, self._side, self._y, self._v)

    @property
    def in_contact(self) -> bool:
        return self._side != FREE

    def deflection(self, side: int) -> float:
        """Tip deflection (m) of the barrier on ``side`` (+1 right, -1 left); 0 when not in contact."""
        if self._side != side:
            return 0.0
        return max(0.0, self.damper.deflection(side, self._p, self._q))

    def voltage(self, side: int) -> float:
        """Patch voltage (V) of the barrier on ``side`` (+1 right, -1 left).

        ``voltage_model = 0``: quasi-static, ``k_V`` times its deflection (0 when not in contact).
        1 and 2: the voltage across the load, exact; it can be negative (while the deflection
        falls) and decays through the load between contacts.
        """
        if self._circuit is None:
            return quasi_static(self.barrier.k_V, self.deflection(side))
        return self._circuit_now(side)[0]

    def power(self, side: int) -> float:
        """Instantaneous power (W) into the load of the barrier on ``side``, ``V^2 / R``.

        0 under ``voltage_model = 0``: the quasi-static voltage is an open-circuit voltage, no
        current flows and nothing is harvested (see ``Simulator.energy``).
        """
        if self._circuit is None:
            return 0.0
        v = self._circuit_now(side)[0]
        return v * v / self.params.R_load

    def _circuit_now(self, side: int) -> tuple[float, float]:
        """Voltage (V) of the barrier on ``side`` now, and its energy harvested so far (J)."""
        br = self._bracket
        return self._circuit.now(side, br.s if br else 0.0, br.powers if br else None, self.t)

    @property
    def base_force(self) -> float:
        """Force (N) the device exerts on its base through ``K`` and ``C``, positive along +x."""
        return self.params.K * (self._p - self._y) + self.params.C * (self._dp - self._v)

    def readings(self) -> dict:
        """Every quantity a host may read at the present instant, by name (:data:`READINGS`), SI:
        the state, the deflections, voltages and load powers of both barriers, the base force, the
        metrics (DI and DI_ls NaN until defined) and the energy ledger's totals. The FMUs' outputs
        are these."""
        return dict(zip(READINGS, self.reading_values()))

    def reading_values(self, energy: bool = True) -> tuple:
        """The values of :meth:`readings`, in the order of :data:`READINGS` (what a host that reads
        them all at every step calls). With ``energy`` False the readings of
        :data:`ENERGY_READINGS` are NaN and not computed (a host that reads none of them now); the
        ledger still books what a full reading would, so that its totals, read later, are the
        same to the bit whichever outputs a host read before."""
        side = self._side
        deflection = self.deflection(side) if side else 0.0
        left, right = (deflection, 0.0) if side == LEFT else (0.0, deflection)
        metrics = self.metrics
        if self._circuit is None:
            # The quasi-static voltage of the barrier in contact; the other one's is 0.
            v = quasi_static(self.barrier.k_V, deflection)
            v_left, v_right = (v, 0.0) if side == LEFT else (0.0, v)
            power_left = power_right = 0.0
        else:
            v_left, v_right = self._circuit_now(LEFT)[0], self._circuit_now(RIGHT)[0]
            R = self.params.R_load
            power_left, power_right = v_left * v_left / R, v_right * v_right / R
        if energy:
            values = self._energy_values()
            dissipated, balance_error, harvested = ledger_totals(*values)
            harvested_left, harvested_right = values[9], values[10]
        else:
            self._ledger.book_pending()
            dissipated = balance_error = harvested = harvested_left = harvested_right = math.nan
        return (self._p, self._dp, self._q, self._dq, left, right, v_left, v_right, self.base_force,
                metrics.impact_count, metrics.last_impact_voltage, metrics.V_rms, metrics.P_ave, metrics.DI,
                dissipated, balance_error, harvested, power_left, power_right, harvested_left, harvested_right,
                metrics.DI_ls)

    @property
    def impacts(self) -> list[Impact]:
        """Logged contacts, oldest first, the one in progress (if any) last."""
        return list(self._impacts) + ([self._open] if self._open else [])

    @property
    def maxima(self) -> list[tuple[float, float]]:
        """Maxima ``(t, p)`` of the main-mass displacement (s, m), oldest first."""
        return list(self._maxima)

    @property
    def metrics(self) -> Metrics:
        # Metrics change only at events; a host reads them every step.
        if self._metrics is None:
            self._metrics = self._acc.metrics(self.params.R_load)
        return self._metrics

    @property
    def energy(self) -> EnergyLedger:
        return EnergyLedger(*self._energy_values())

    def _energy_values(self) -> tuple:
        """The fields of :attr:`energy`, in its order (a plain tuple: a host reads them every step)."""
        kinetic, potential_K, potential_Keq = self.damper.mechanical_energy(self._side, self._p, self._dp, self._q,
                                                                            self._dq, self._y)
        br = self._bracket
        dissipated_C, dissipated_Ceq, plastic, work_base = self._ledger.flows(br)
        initial = self._ledger.initial
        circuit = self._circuit
        if circuit is None:
            return (kinetic, potential_K, potential_Keq, dissipated_C, dissipated_Ceq, plastic, work_base, initial,
                    0.0, 0.0, 0.0, 0.0, 0.0)
        v_left, harvested_left = self._circuit_now(LEFT)
        v_right, harvested_right = self._circuit_now(RIGHT)
        converted = circuit.converted_now(br.s, br.powers) if br else circuit.converted
        return (kinetic, potential_K, potential_Keq, dissipated_C, dissipated_Ceq, plastic, work_base, initial,
                0.5 * self.barrier.C_p * (v_left * v_left + v_right * v_right), harvested_left, harvested_right,
                converted, converted if self.damper.coupled else 0.0)

    @property
    def contact_frequency(self) -> float:
        """rad/s: undamped angular frequency ``sqrt(K_eq / mu)`` of the relative motion in contact
        (short-circuited patch), ``mu`` the reduced mass of ``M - M_eq`` and ``m + M_eq``."""
        return self.damper.contact_frequency

    @property
    def bracket_lengths(self) -> dict[str, float]:
        """Longest bracket (s) of each phase: ``THETA / rho(A)`` (see ``propagation.py``)."""
        return {"free": self._free.h, "contact": self._contact[RIGHT].h}

    @property
    def longest_bracket(self) -> float:
        """The longest bracket (s) of any phase."""
        return max(self._free.h, self._contact[RIGHT].h)

    # ------------------------------------------------------------------ saving state
    def snapshot(self) -> dict:
        """The full internal state as a JSON-safe dict (floats, ints, lists)."""
        return snapshot_of(self)

    @classmethod
    def restore(cls, params: Parameters, snapshot: dict, log_limit: int | None = None) -> "Simulator":
        """A simulator of ``params`` in the state saved by :meth:`snapshot`."""
        sim = cls(params, log_limit=log_limit)
        restore_into(sim, snapshot)
        return sim
