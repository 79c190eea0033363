"""The damper as a Model Exchange FMU, whatever the FMI version: states, derivatives, event
indicators and event updates (docs/model.md sections 2-6).

Interface-independent, as :mod:`piezo_fmu.fmi.cosim` is for co-simulation: the FMI 3.0 slave
(:mod:`piezo_fmu.fmi.fmi3`) maps pythonfmu3's calls onto :class:`ModelExchange`, which runs a
:class:`~piezo_fmu.fmi.me_run.Run` on the parameters and inputs the host set. The physics is the
model's (:class:`piezo_fmu.model.Damper`), written nowhere else: the phase matrices give the
accelerations, the energy rates and the voltage models the other derivatives, the deflection is
the event function of the contacts, the switch rules give the state jumps, and the energies and
the metric accumulators of the solver give the outputs.

- Continuous states (:data:`piezo_fmu.fmi.variables.STATES`): ``p, p', q, q'`` (absolute), the
  two patch voltages (circuit models 1 and 2; 0 under the quasi-static model 0), and the
  quadratures of the energy ledger: dissipation in ``C`` and ``C_eq``, work of the base, the
  energy harvested in each load, the energy converted by the barriers.
- Discrete state: the phase (free, or contact on the right or the left), the plastic losses of
  the switches, the metric accumulators, the largest deflection and ``|V|`` of the open contact,
  and whether ``p`` was rising at the last event.
- Event indicators (:data:`piezo_fmu.fmi.variables.INDICATORS`), the same five in every phase:
  ``q - p - d/2`` and ``p - q - d/2`` (each barrier's deflection: a rising zero is a contact onset,
  a falling zero of the one in contact a separation), ``delta'`` in contact (its falling zero is
  the peak deflection), ``p'`` (its falling zeros are the maxima of ``p``), and ``V'`` of the
  barrier in contact under the circuit models (peak ``|V|``); 1 where a phase does not use one.
  Within its rounding level of zero an indicator reads that level, signed by the side it is held
  on (:func:`piezo_fmu.fmi.me_run.held`): no host sees an exact zero, nor a crossing that rounding
  alone makes.

An event update decides from the state which event happened (the direction of a crossing from
the relative velocity, docs/model.md section 3.6), applies the switch rules, and records impacts,
maxima and impact voltages. After a switch the impact mass is put on the barrier's surface to
within one rounding, on the side of the new phase, so that no host sees the indicator that fired
at zero again (hosts treat an exact zero differently).

The inputs ``y`` and ``v`` are continuous-time inputs: every evaluation uses the values set at
that moment, and the work of the base is ``-int v (K (p - y) + C (p' - v)) dt``, which closes the
ledger when the host's ``v`` is the derivative of its ``y``.
"""

from __future__ import annotations

import copy
import math
from typing import Callable, NamedTuple, Optional

from piezo_fmu.fmi.cosim import CoSimulation, publish
from piezo_fmu.fmi.me_run import UNUSED, Equations, Run
from piezo_fmu.fmi.variables import BY_NAME, INDICATORS, STATES

_Y, _V = BY_NAME["base_displacement"], BY_NAME["base_velocity"]


class Update(NamedTuple):
    """What an event update tells the host (FMI's flags)."""

    discrete_states_need_update: bool = False
    terminate_simulation: bool = False
    nominals_changed: bool = False
    values_changed: bool = False


class ModelExchange:
    """One Model Exchange instance of the damper, on the values (parameters, inputs) of a
    :class:`~piezo_fmu.fmi.cosim.CoSimulation` instance, so that what a host set before choosing
    the interface holds in either.

    Parameters
    ----------
    values : the co-simulation instance that holds every variable's value by value reference.
    log_error : takes the message of every refused value or failed update (logged with the error
        status by the slave).
    """

    def __init__(self, values: CoSimulation, log_error: Callable[[str], None]):
        self.values = values
        self._log_error = log_error
        self._run: Optional[Run] = None
        self._time = values.time
        self._fault: Optional[str] = None  # why the run cannot go on

    @property
    def run(self) -> Optional[Run]:
        """The run, (re)built from the start values until the instance leaves initialization."""
        sim = self.values.simulator()
        damper = None if sim is None else sim.damper
        if damper is None:
            self._run = None
        elif self._run is None or self._run.eq.damper is not damper:
            now = self.values.now
            self._run = Run(Equations(damper), self._time, now[_Y], now[_V])
        return self._run

    @property
    def time(self) -> float:
        return self._time

    def set_time(self, t: float) -> None:
        self._time = t
        if self._run is not None:
            self._run.t = t

    def states(self) -> list:
        run = self.run
        return list(run.x) if run is not None else [math.nan] * len(STATES)

    def set_states(self, values) -> None:
        run = self.run
        if run is not None:
            run.x = [float(value) for value in values]

    def derivatives(self) -> list:
        run = self.run
        if run is None:
            return [0.0] * len(STATES)
        now = self.values.now
        return run.eq.derivatives(run.x, run.side, now[_Y], now[_V])

    def indicators(self) -> list:
        run = self.run
        return run.indicators() if run is not None else [UNUSED] * len(INDICATORS)

    def nominals(self) -> list:
        run = self.run
        return run.eq.nominals() if run is not None else [1.0] * len(STATES)

    def update(self) -> Update:
        """The event update (and the initial one): the switches due, the events recorded."""
        run = self.run
        fault = self._fault or self.values.fault
        y, v = self.values.now[_Y], self.values.now[_V]
        if fault is None and run is not None and not (math.isfinite(y) and math.isfinite(v)):
            fault = f"input base_displacement = {y!r}, base_velocity = {v!r} at t = {self._time!r} s is not finite"
        if fault is None and run is not None:
            try:
                return Update(values_changed=run.update(y, v))
            except Exception as error:  # noqa: BLE001 - reported through FMI, never raised
                fault = self._fault = f"event update at t = {self._time!r} s failed: {error}"
        self._log_error(f"{fault or 'no model'}: the simulation must stop")
        return Update(terminate_simulation=True)

    def get(self, vrs) -> list:
        """The values of the table's variables ``vrs`` (value references), outputs from the run."""
        run = self.run
        if run is None:
            return self.values.get(vrs)
        now = list(self.values.now)  # the co-simulation's outputs stay its own
        publish(now, run.readings(now[_Y], now[_V]))
        return [now[vr] for vr in vrs]

    def locals(self, names) -> list:
        run = self.run
        if run is None:
            return [math.nan] * len(names)
        now = self.values.now
        values = run.locals(now[_Y], now[_V])
        return [values[name] for name in names]

    def get_state(self) -> dict:
        run = self.run
        return {"time": self._time, "fault": self._fault, "run": run.snapshot() if run is not None else None}

    def set_state(self, state: dict) -> None:
        state = copy.deepcopy(state)
        self._time, self._fault = state["time"], state["fault"]
        run = self.run
        if run is not None and state["run"] is not None:
            run.restore(state["run"])


def locals_of_core(values: CoSimulation, names) -> list:
    """The Model Exchange locals ``names`` of the co-simulation core of ``values`` where it stands
    (NaN without a core)."""
    sim = values.simulator()
    if sim is None:
        return [math.nan] * len(names)
    by_name = Run.of_core(sim).locals(sim.state.y, sim.state.v)
    return [by_name[name] for name in names]


__all__ = ["ModelExchange", "UNUSED", "Update", "locals_of_core"]
