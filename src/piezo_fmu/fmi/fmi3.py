"""The FMI 3.0 slave of the piezo-impact damper (pythonfmu3): co-simulation and Model Exchange.

A thin adapter, as :mod:`piezo_fmu.fmi.fmi2` is for FMI 2.0: the calls of pythonfmu3 are mapped
onto :class:`piezo_fmu.fmi.cosim.CoSimulation`, so that the FMI 3.0 co-simulation gives the FMI 2.0
one's bits at the same communication points, and onto :class:`piezo_fmu.fmi.me.ModelExchange`.
The variables are those of :data:`piezo_fmu.fmi.variables.VARIABLES` under the same value
references (Real as Float64, Integer as Int32), followed by the independent variable ``time`` and
the locals of Model Exchange (:data:`piezo_fmu.fmi.variables.MODEL_EXCHANGE`).
:mod:`piezo_fmu.build` turns this script into ``fmus/PiezoImpactDamper3.fmu`` and completes its
modelDescription.

pythonfmu3 does not tell the slave which interface the host instantiated. The first call that
only one interface makes decides: ``do_step`` co-simulation; ``set_time``,
``set_continuous_states``, ``get_continuous_states``, ``get_continuous_state_derivatives`` or
``get_event_indicators`` Model Exchange. ``update_discrete_states`` runs Model Exchange's event
update without deciding (fmpy's co-simulation calls it too, in its event mode); in a
co-simulation it changes nothing. Parameters and inputs live in the co-simulation's values either
way, so what a host sets before the decision holds in both.

Inside the FMU this file is the top-level module ``piezo_fmu_slave3``; imports are absolute.

Nothing escapes as an exception: pythonfmu3's binary turns one into fmi3Fatal and releases
objects it still uses, which can crash the host later. A refused value or call is logged with
the error status (naming the variable, the value and the allowed range) and a refused step
returns fmi3Error; Model Exchange's calls cannot return a status in pythonfmu3, so a Model
Exchange run that cannot go on (bad start values, a fixed parameter set later) logs the error
and asks the host to terminate at its next event update. Anything unexpected is logged with the
fatal status.
"""

from __future__ import annotations

import math
from typing import Dict, List

from pythonfmu3 import (CoSimulation, DefaultExperiment, Fmi3Causality, Fmi3SlaveBase, Fmi3Status, Fmi3StepResult,
                        Fmi3UpdateDiscreteStatesResult, Fmi3Variability, Float64, Int32, ModelExchange)
from pythonfmu3.enums import Fmi3Initial

from piezo_fmu.fmi import cosim, me
from piezo_fmu.fmi.cosim import TYPE_NAMES, guarded, no_values, type_problem
from piezo_fmu.fmi.variables import FMI3_VARIABLES, INDICATORS, STATES, VARIABILITY, VARIABLES, Variable

#: The value reference of the independent variable, after the table; the locals follow it.
TIME = len(VARIABLES)
#: The value references of each FMI 2.0 type, over every variable of the FMI 3.0 FMU.
REFERENCES = {kind: frozenset(vr for vr, spec in enumerate(FMI3_VARIABLES) if spec.type == kind)
              for kind in ("Real", "Integer")}
#: The value references of the table (served by the co-simulation's or Model Exchange's values).
TABLE = frozenset(range(TIME))
BY_NAME = {spec.name: vr for vr, spec in enumerate(FMI3_VARIABLES)}
#: The interfaces, once decided.
CO_SIMULATION, MODEL_EXCHANGE = "co-simulation", "model exchange"


def model_variable(spec: Variable, getter, setter=None, derivative=None):
    """The pythonfmu3 variable for one row of the table (units, bounds and starts are written by
    the build, from the same table)."""
    initial = Fmi3Initial.exact if spec.causality == "parameter" else None
    kwargs = dict(causality=Fmi3Causality[spec.causality],
                  variability=Fmi3Variability[VARIABILITY[spec.causality, spec.type]],
                  initial=initial, description=spec.description, getter=getter, setter=setter)
    if spec.type == "Integer":
        return Int32(spec.name, **kwargs)
    return Float64(spec.name, derivative=derivative, **kwargs)


def update_result(update: me.Update) -> Fmi3UpdateDiscreteStatesResult:
    """pythonfmu3's result of an event update, with the attribute names its binary reads
    (``discreteStatesNeedUpdate``, ``nominalContinuousStatesChanged``): the dataclass spells them
    otherwise, and a host that presets the flags true would otherwise never see them cleared."""
    result = Fmi3UpdateDiscreteStatesResult(
        discreteStateNeedsUpdate=update.discrete_states_need_update, terminateSimulation=update.terminate_simulation,
        nominalsOfContinuousStatesChanged=update.nominals_changed,
        valuesOfContinuousStatesChanged=update.values_changed)
    result.discreteStatesNeedUpdate = update.discrete_states_need_update
    result.nominalContinuousStatesChanged = update.nominals_changed
    return result


class PiezoImpactDamper3(Fmi3SlaveBase, ModelExchange, CoSimulation):
    """Piezo-impact damper (Afsharfard and Farshidianfar 2014): main mass, impact mass and two
    piezoelectric cantilever barriers, driven by base motion; exact event-driven core."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "piezo-fmu"
        self.description = ("Piezo-impact damper (Afsharfard and Farshidianfar 2014) driven by base motion; "
                            "exact event-driven core (co-simulation) or its equations (Model Exchange). "
                            "Needs Python 3 with numpy.")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)
        self.time = 0.0  # pythonfmu3 requires it; the instance's own time is self._time()
        self._cosim = cosim.CoSimulation(self._refuse)
        self._me = me.ModelExchange(self._cosim, self._refuse)
        self._mode = None  # CO_SIMULATION or MODEL_EXCHANGE once a call has decided

    def to_xml(self, model_options: Dict[str, str] = dict()):  # noqa: B006 - pythonfmu3's signature
        # pythonfmu3's variable objects are made only for the model description.
        if not self.vars:
            values = self._cosim
            for vr, spec in enumerate(FMI3_VARIABLES):
                setter = (lambda value, vr=vr: values.set([vr], [value])) if spec.causality in ("parameter", "input") else None
                state = spec.name[4:-1] if spec.name.startswith("der(") else None
                self.register_variable(model_variable(spec, lambda vr=vr: self._value(vr), setter,
                                                      BY_NAME[state] if state else None), nested=False)
            for name in INDICATORS:
                self.register_event_indicator(BY_NAME[name])
        return super().to_xml(model_options)

    # -- errors: logged, never raised ------------------------------------------------------------

    def _refuse(self, message: str) -> None:
        self.log(message, Fmi3Status.error)

    def _log_fatal(self, message: str) -> None:
        self.log(message, Fmi3Status.fatal)

    def _runs_as(self, mode: str) -> bool:
        """Decide the interface on the first call only ``mode`` makes; False (and a logged error)
        when the instance already runs as the other one."""
        if self._mode is None:
            self._mode = mode
        elif self._mode != mode:
            self._refuse(f"this instance runs as {self._mode}: a {mode} call is not allowed")
            return False
        return True

    # -- values ---------------------------------------------------------------------------------

    def _time(self) -> float:
        return self._me.time if self._mode == MODEL_EXCHANGE else self._cosim.time

    def _value(self, vr: int):
        return self._values([vr], FMI3_VARIABLES[vr].type)[0]

    def _values(self, vrs: List[int], kind: str) -> list:
        problem = type_problem(vrs, kind, TYPE_NAMES[3], FMI3_VARIABLES)
        if problem is not None:
            self._refuse(f"get: {problem}")
            return no_values(vrs, kind)
        source = self._me if self._mode == MODEL_EXCHANGE else self._cosim
        if TABLE.issuperset(vrs):
            return source.get(vrs)
        names = [FMI3_VARIABLES[vr].name for vr in vrs if vr > TIME]
        local = iter(self._me.locals(names) if self._mode == MODEL_EXCHANGE else me.locals_of_core(self._cosim, names))
        return [source.get([vr])[0] if vr < TIME else self._time() if vr == TIME else next(local) for vr in vrs]

    def _assign(self, vrs: List[int], values: list, kind: str) -> None:
        problem = type_problem(vrs, kind, TYPE_NAMES[3], FMI3_VARIABLES)
        if problem is None:
            fixed = [vr for vr in vrs if FMI3_VARIABLES[vr].causality not in ("parameter", "input")]
            if fixed:
                vr = fixed[0]
                problem = (f"variable {FMI3_VARIABLES[vr].name} (valueReference={vr}, causality "
                           f"{FMI3_VARIABLES[vr].causality}) cannot be set")
        if problem is not None:
            self._refuse(f"set: {problem}")
            return
        self._cosim.set(vrs, values)

    @guarded(lambda vrs: no_values(vrs, "Real"))
    def get_float64(self, vrs: List[int]) -> List[float]:
        return self._values(vrs, "Real")

    @guarded(lambda vrs: no_values(vrs, "Integer"))
    def get_int32(self, vrs: List[int]) -> List[int]:
        return self._values(vrs, "Integer")

    @guarded(lambda vrs, values: None)
    def set_float64(self, vrs: List[int], values: List[float]):
        self._assign(vrs, values, "Real")

    @guarded(lambda vrs, values: None)
    def set_int32(self, vrs: List[int], values: List[int]):
        self._assign(vrs, values, "Integer")

    @guarded(lambda vrs: no_values(vrs, "Int64"))
    def get_int64(self, vrs):
        return self._values(vrs, "Int64")

    @guarded(lambda vrs: no_values(vrs, "UInt64"))
    def get_uint64(self, vrs):
        return self._values(vrs, "UInt64")

    @guarded(lambda vrs: no_values(vrs, "Boolean"))
    def get_boolean(self, vrs):
        return self._values(vrs, "Boolean")

    @guarded(lambda vrs: no_values(vrs, "String"))
    def get_string(self, vrs):
        return self._values(vrs, "String")

    @guarded(lambda vrs, values: None)
    def set_int64(self, vrs, values):
        self._assign(vrs, values, "Int64")

    @guarded(lambda vrs, values: None)
    def set_uint64(self, vrs, values):
        self._assign(vrs, values, "UInt64")

    @guarded(lambda vrs, values: None)
    def set_boolean(self, vrs, values):
        self._assign(vrs, values, "Boolean")

    @guarded(lambda vrs, values: None)
    def set_string(self, vrs, values):
        self._assign(vrs, values, "String")

    # -- life cycle -----------------------------------------------------------------------------

    @guarded(lambda: None)
    def exit_initialization_mode(self):
        self._cosim.exit_initialization()

    @guarded(lambda current_time, step_size: Fmi3StepResult(status=Fmi3Status.fatal))
    def do_step(self, current_time: float, step_size: float) -> Fmi3StepResult:
        if not self._runs_as(CO_SIMULATION):
            return Fmi3StepResult(status=Fmi3Status.error)
        self._cosim.start_at(current_time)
        if not self._cosim.step(current_time, step_size):
            return Fmi3StepResult(status=Fmi3Status.error)
        return Fmi3StepResult()

    # -- Model Exchange -------------------------------------------------------------------------

    @guarded(lambda time: None)
    def set_time(self, time: float):
        if self._runs_as(MODEL_EXCHANGE):
            self.time = time
            self._me.set_time(time)

    @guarded(lambda values: None)
    def set_continuous_states(self, values: List[float]):
        if self._runs_as(MODEL_EXCHANGE):
            self._me.set_states(values)

    @guarded(lambda: [math.nan] * len(STATES))
    def get_continuous_states(self) -> List[float]:
        return self._me.states() if self._runs_as(MODEL_EXCHANGE) else [math.nan] * len(STATES)

    @guarded(lambda: [math.nan] * len(STATES))
    def get_continuous_state_derivatives(self) -> List[float]:
        return self._me.derivatives() if self._runs_as(MODEL_EXCHANGE) else [math.nan] * len(STATES)

    @guarded(lambda: [me.UNUSED] * len(INDICATORS))
    def get_event_indicators(self) -> List[float]:
        return self._me.indicators() if self._runs_as(MODEL_EXCHANGE) else [me.UNUSED] * len(INDICATORS)

    @guarded(lambda size: [1.0] * size)
    def get_nominals_of_continuous_states(self, size: int) -> List[float]:
        return self._me.nominals()[:size] if self._mode != CO_SIMULATION else [1.0] * size

    def get_number_of_continuous_states(self) -> int:
        return len(STATES)

    def get_number_of_event_indicators(self) -> int:
        return len(INDICATORS)

    @guarded(lambda: update_result(me.Update(terminate_simulation=True)))
    def update_discrete_states(self) -> Fmi3UpdateDiscreteStatesResult:
        # A co-simulation handles its events inside its steps: nothing to update.
        return update_result(self._me.update() if self._mode != CO_SIMULATION else me.Update())

    # -- FMU state ------------------------------------------------------------------------------

    @guarded(lambda: None)
    def _get_fmu_state(self) -> dict:
        return {"mode": self._mode, "co_simulation": self._cosim.get_state(),
                "model_exchange": self._me.get_state() if self._mode == MODEL_EXCHANGE else None}

    @guarded(lambda state: None)
    def _set_fmu_state(self, state: dict) -> None:
        self._mode = state["mode"]
        self._cosim.set_state(state["co_simulation"])
        if state["model_exchange"] is not None:
            self._me.set_state(state["model_exchange"])

