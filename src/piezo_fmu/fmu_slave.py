"""The FMI 2.0 co-simulation slave of the piezo-impact damper: a table of variables.

Each variable forwards to the simulation core (:class:`piezo_fmu.Simulator`); there is no
physics here. The FMI side lives here and in :mod:`piezo_fmu.fmu_build`, which turns this
script into ``fmus/PiezoImpactDamper.fmu`` (``python -m piezo_fmu.fmu_build``) and completes the
modelDescription with the units, bounds and structure this table declares.

Inside the FMU this file is the top-level module ``piezo_fmu_slave`` and imports the core from
the ``piezo_fmu`` package bundled beside it in ``resources/``. Imports are absolute for that
reason. The module holds no mutable state: every instance keeps its own.

Errors never escape as exceptions (pythonfmu turns those into ``fmi2Fatal`` and the instance is
lost). A bad parameter, a non-finite input, a non-positive step or a step that does not start at
the current time is logged with ``fmi2Error`` and the step returns ``fmi2Discard``; the instance
stays usable (set finite inputs and step again, or reset it).
"""

from __future__ import annotations

import copy
import math
from typing import Callable, Dict, List, NamedTuple, Optional

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from piezo_fmu import Parameters, Simulator, parameter_info

class Variable(NamedTuple):
    """One FMU variable: what the modelDescription says of it and how to read it from the core.

    ``unit``, ``min`` and ``max`` are written by :mod:`piezo_fmu.fmu_build` (pythonfmu 0.7.0
    writes none of them). ``read`` maps a :class:`CoreView` of the core to an output's value,
    or the :class:`Simulator` to a calculated parameter's.
    """

    name: str
    type: str  # "Real" or "Integer"
    causality: str  # "parameter", "input", "output" or "calculatedParameter"
    unit: Optional[str]  # None for Integer variables: FMI 2.0 gives Integer no unit
    description: str
    min: Optional[float] = None
    max: Optional[float] = None
    start: Optional[float] = None  # parameters and inputs only
    read: Optional[Callable] = None  # outputs only


def _zero_until_defined(value: float) -> float:
    """The core reports a not-yet-defined metric as NaN; the FMU output is 0 until then."""
    return 0.0 if math.isnan(value) else value


def _parameter_variables() -> tuple:
    """Every core parameter, under its own name, unit, description, bound and default.

    A parameter whose default is an ``int`` (``barrier_mode``) is an FMI Integer, the rest Real.
    """
    table = []
    for name, info in parameter_info().items():
        bound = info["bound"]
        is_integer = type(info["default"]) is int
        table.append(Variable(
            name=name,
            type="Integer" if is_integer else "Real",
            causality="parameter",
            unit=None if is_integer else info["unit"],
            description=info["description"],
            min=bound.lo if math.isfinite(bound.lo) else None,
            max=bound.hi if math.isfinite(bound.hi) else None,
            start=info["default"],
        ))
    return tuple(table)


INPUTS = (
    Variable("base_displacement", "Real", "input", "m",
             "Base displacement y at the start of the step; within a step y = y_k + v_k (t - t_k)",
             start=0.0),
    Variable("base_velocity", "Real", "input", "m/s",
             "Base velocity v_b, constant within a step (leave at 0 for a zero-order hold of y)",
             start=0.0),
)

_FIRST_OUTPUTS = (
    Variable("main_displacement", "Real", "output", "m",
             "Absolute displacement p of the main mass", read=lambda core: core.state.p),
    Variable("main_velocity", "Real", "output", "m/s",
             "Absolute velocity dp/dt of the main mass", read=lambda core: core.state.dp),
    Variable("impactor_displacement", "Real", "output", "m",
             "Absolute displacement q of the impact mass", read=lambda core: core.state.q),
    Variable("impactor_velocity", "Real", "output", "m/s",
             "Absolute velocity dq/dt of the impact mass", read=lambda core: core.state.dq),
    Variable("deflection_left", "Real", "output", "m",
             "Tip deflection of the left barrier (r = -d/2); 0 while not in contact",
             min=0.0, read=lambda core: core.sim.deflection(-1)),
    Variable("deflection_right", "Real", "output", "m",
             "Tip deflection of the right barrier (r = +d/2); 0 while not in contact",
             min=0.0, read=lambda core: core.sim.deflection(+1)),
    Variable("voltage_left", "Real", "output", "V",
             "Voltage of the left barrier's piezoelectric patch (voltage_model 0: quasi-static, eqs. 25-28, "
             ">= 0; 1 and 2: across the load, signed)",
             read=lambda core: core.sim.voltage(-1)),
    Variable("voltage_right", "Real", "output", "V",
             "Voltage of the right barrier's piezoelectric patch (voltage_model 0: quasi-static, eqs. 25-28, "
             ">= 0; 1 and 2: across the load, signed)",
             read=lambda core: core.sim.voltage(+1)),
    Variable("base_force", "Real", "output", "N",
             "Force the device exerts on its base (spring K and damper C of the main mass), along +x",
             read=lambda core: core.sim.base_force),
    Variable("impact_count", "Integer", "output", None,
             "Number of impacts (contact onsets) so far, both barriers", min=0,
             read=lambda core: core.metrics.impact_count),
    Variable("last_impact_voltage", "Real", "output", "V",
             "Peak voltage of the latest completed impact (eq. 28); 0 before the first", min=0.0,
             read=lambda core: core.metrics.last_impact_voltage),
    Variable("voltage_rms", "Real", "output", "V",
             "RMS of the peak voltages of the impacts completed so far (eq. 30)", min=0.0,
             read=lambda core: core.metrics.V_rms),
    Variable("average_power", "Real", "output", "W",
             "Average power V_rms^2 / R_load (eq. 30)", min=0.0,
             read=lambda core: core.metrics.P_ave),
    Variable("damping_inclination", "Real", "output", "m/s",
             "Damping inclination (P1 - P2) / (t2 - t1) from the first two maxima of p (eq. 29); "
             "0 until two maxima exist",
             read=lambda core: _zero_until_defined(core.metrics.DI)),
    Variable("energy_dissipated", "Real", "output", "J",
             "Energy dissipated since the start (damping, contact, barrier capture and release)",
             min=0.0, read=lambda core: core.energy.dissipated),
    Variable("energy_balance_error", "Real", "output", "J",
             "Energy ledger residual: energy now - (initial energy + work by the base - dissipated); "
             "0 to rounding",
             read=lambda core: core.energy.balance_error),
    Variable("harvested_energy", "Real", "output", "J",
             "Energy harvested in the loads of both barriers since the start, integral of V^2/R_load dt "
             "(voltage_model 1 and 2; 0 under the quasi-static model 0, an open-circuit voltage)",
             min=0.0, read=lambda core: core.energy.harvested),
    Variable("power_left", "Real", "output", "W",
             "Instantaneous power V^2/R_load into the left barrier's load (0 under voltage_model 0)",
             min=0.0, read=lambda core: core.sim.power(-1)),
    Variable("power_right", "Real", "output", "W",
             "Instantaneous power V^2/R_load into the right barrier's load (0 under voltage_model 0)",
             min=0.0, read=lambda core: core.sim.power(+1)),
    Variable("harvested_energy_left", "Real", "output", "J",
             "Energy harvested in the left barrier's load since the start, integral of V^2/R_load dt "
             "(0 under voltage_model 0)",
             min=0.0, read=lambda core: core.energy.harvested_left),
    Variable("harvested_energy_right", "Real", "output", "J",
             "Energy harvested in the right barrier's load since the start, integral of V^2/R_load dt "
             "(0 under voltage_model 0)",
             min=0.0, read=lambda core: core.energy.harvested_right),
)

#: Quantities the FMU derives from its parameters (FMI calculatedParameter): what a designer
#: needs to choose a load, ``R_opt ~ 1 / (contact_frequency patch_capacitance)``.
CALCULATED = (
    Variable("patch_capacitance", "Real", "calculatedParameter", "F",
             "Capacitance C_p = eps33 W_p L_p / t_p of each barrier's piezoelectric patch (MODEL.md section 5)",
             min=0.0, read=lambda sim: sim.barrier.C_p),
    Variable("contact_frequency", "Real", "calculatedParameter", "rad/s",
             "Undamped angular frequency sqrt(K_eq / mu) of the relative motion in contact, mu the reduced "
             "mass of M - M_eq and m + M_eq (short-circuited patch)",
             min=0.0, read=lambda sim: sim.contact_frequency),
)

#: Outputs added after the calculated parameters (appended, so that no value reference moved).
_LATER_OUTPUTS = (
    Variable("damping_inclination_ls", "Real", "output", "m/s",
             "Robust damping inclination: minus the least-squares slope of the positive maxima of p that "
             "follow an impact (a companion of eq. 29, insensitive to a double maximum); 0 until two such "
             "maxima exist",
             read=lambda core: _zero_until_defined(core.metrics.DI_ls)),
)

#: The whole table, in value-reference order: parameters, inputs, outputs, calculated parameters,
#: then the later outputs (each group appended, so that the earlier value references stay as they were).
VARIABLES = _parameter_variables() + INPUTS + _FIRST_OUTPUTS + CALCULATED + _LATER_OUTPUTS
#: Every output, in value-reference order.
OUTPUTS = tuple(spec for spec in VARIABLES if spec.causality == "output")

_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input,
              "output": Fmi2Causality.output, "calculatedParameter": Fmi2Causality.calculatedParameter}
_VARIABILITY = {("parameter", "Real"): Fmi2Variability.fixed,
                ("parameter", "Integer"): Fmi2Variability.fixed,
                ("input", "Real"): Fmi2Variability.continuous,
                ("output", "Real"): Fmi2Variability.continuous,
                ("output", "Integer"): Fmi2Variability.discrete,
                ("calculatedParameter", "Real"): Fmi2Variability.fixed}


def scalar_variable(spec: Variable, getter: Callable, setter: Optional[Callable] = None):
    """The pythonfmu variable for one row of the table."""
    kind = Integer if spec.type == "Integer" else Real
    initial = Fmi2Initial.exact if spec.causality == "parameter" else None
    return kind(spec.name, causality=_CAUSALITY[spec.causality],
                variability=_VARIABILITY[spec.causality, spec.type], initial=initial,
                description=spec.description, getter=getter, setter=setter)


class CoreView:
    """The core read at one instant, each aggregate built once for all the outputs."""

    __slots__ = ("sim", "state", "metrics", "energy")

    def __init__(self, sim: Simulator):
        self.sim, self.state, self.metrics, self.energy = sim, sim.state, sim.metrics, sim.energy


_READERS = tuple(spec.read for spec in OUTPUTS)
#: The FMI type of each variable, by value reference.
_KINDS = tuple("Integer" if spec.type == "Integer" else "Real" for spec in VARIABLES)
#: The value references of each FMI type.
_REFERENCES = {kind: frozenset(vr for vr, k in enumerate(_KINDS) if k == kind) for kind in ("Real", "Integer")}
#: Brackets one communication step may need at the least (a few minutes of CPU): a longer step is
#: refused at once rather than left to run for hours in the host.
MAX_BRACKETS_PER_STEP = 1e7
#: Output values before the core exists (bad start values): NaN, and 0 for the Integer.
_NO_OUTPUTS = tuple(0 if spec.type == "Integer" else math.nan for spec in OUTPUTS)


def on_nanosecond_grid(t: float) -> float:
    """``t`` moved to the nearest whole nanosecond when it lies within ``1e-12 * max(1, |t|)`` s
    of it, else ``t`` unchanged."""
    snapped = round(t * 1e9) / 1e9
    return snapped if abs(snapped - t) <= 1e-12 * max(1.0, abs(t)) else t


def _step_end(t_now: float, current_time: float, step_size: float) -> float:
    """Where a step ends: ``current_time + step_size``, on the whole nanosecond it is within
    rounding of (so that masters that round their time differently agree), never at or before
    the FMU's own time."""
    end = current_time + step_size
    snapped = on_nanosecond_grid(end)
    return snapped if snapped > t_now else end


class PiezoImpactDamper(Fmi2Slave):
    """Piezo-impact damper (Afsharfard and Farshidianfar 2014): main mass, impact mass and two
    piezoelectric cantilever barriers, driven by base motion; exact event-driven core."""

    author = "piezo-fmu"
    description = ("Piezo-impact damper (Afsharfard and Farshidianfar 2014) driven by base motion; "
                   "exact event-driven core. Needs Python 3 with numpy.")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._values = {spec.name: spec.start for spec in VARIABLES if spec.causality == "parameter"}
        self._inputs = {spec.name: spec.start for spec in INPUTS}
        self._start_time = 0.0
        self._sim: Optional[Simulator] = None
        self._stale = True  # start values changed since the core was built
        self._stepping = False  # past fmi2ExitInitializationMode
        self._fault: Optional[str] = None  # why every further step must fail
        self._outputs: Optional[list] = None  # output values at the present instant, once read
        # The getters and setters by value reference (the order of VARIABLES). pythonfmu's variable
        # objects are made only for the model description (to_xml): every fmi2Reset builds a new
        # instance, and 54 of them cost 5% of a 2 s sweep point.
        self._getters, self._setters = zip(*(self._access(spec) for spec in VARIABLES))

    # -- the table, bound to this instance ------------------------------------------------------

    def _access(self, spec: Variable) -> tuple[Callable, Optional[Callable]]:
        """The getter and the setter (None: not settable) of one variable."""
        name = spec.name
        if spec.causality == "parameter":
            return (lambda: self._values[name]), (lambda value: self._set_parameter(name, value))
        if spec.causality == "input":
            return (lambda: self._inputs[name]), (lambda value: self._set_input(name, value))
        if spec.causality == "calculatedParameter":
            # Fixed once initialized: read on request, not with every step's outputs.
            return (lambda: spec.read(sim) if (sim := self._core()) is not None else math.nan), None
        index = OUTPUTS.index(spec)
        return (lambda: (self._outputs or self._read_outputs())[index]), None

    def to_xml(self, model_options: Dict[str, str] = dict()):  # noqa: B006 - pythonfmu's signature
        if not self.vars:
            for spec, getter, setter in zip(VARIABLES, self._getters, self._setters):
                self.register_variable(scalar_variable(spec, getter, setter), nested=False)
        return super().to_xml(model_options)

    @staticmethod
    def _checked(vrs, kind: str):
        """``vrs``, each checked to be a variable of ``kind`` (as pythonfmu's own accessors do)."""
        if not _REFERENCES.get(kind, frozenset()).issuperset(vrs):
            for vr in vrs:
                if not 0 <= vr < len(_KINDS):
                    raise KeyError(f"no variable has valueReference={vr}")
                if _KINDS[vr] != kind:
                    raise TypeError(f"Variable with valueReference={vr} is not of type {kind}!")
        return vrs

    def get_real(self, vrs: List[int]) -> List[float]:
        getters = self._getters
        return [float(getters[vr]()) for vr in self._checked(vrs, "Real")]

    def get_integer(self, vrs: List[int]) -> List[int]:
        getters = self._getters
        return [int(getters[vr]()) for vr in self._checked(vrs, "Integer")]

    def set_real(self, vrs: List[int], values: List[float]):
        self._set(self._checked(vrs, "Real"), values)

    def set_integer(self, vrs: List[int], values: List[int]):
        self._set(self._checked(vrs, "Integer"), values)

    def _set(self, vrs: List[int], values: list) -> None:
        for vr, value in zip(vrs, values):
            setter = self._setters[vr]
            if setter is None:
                raise TypeError(f"variable {VARIABLES[vr].name} (valueReference={vr}, causality "
                                f"{VARIABLES[vr].causality}) cannot be set")
            setter(value)

    def get_boolean(self, vrs: List[int]) -> List[bool]:
        self._checked(vrs, "Boolean")
        return []

    def get_string(self, vrs: List[int]) -> List[str]:
        self._checked(vrs, "String")
        return []

    def set_boolean(self, vrs: List[int], values: List[bool]):
        self._checked(vrs, "Boolean")

    def set_string(self, vrs: List[int], values: List[str]):
        self._checked(vrs, "String")

    def _set_parameter(self, name: str, value) -> None:
        if self._stepping:
            if value == self._values[name]:
                return  # hosts that set every start value again change nothing
            self._fault = f"parameter {name} is fixed: it cannot be set to {value!r} after initialization"
            self.log(self._fault, Fmi2Status.error)
            return
        self._values[name] = value
        self._start_values_changed()

    def _set_input(self, name: str, value: float) -> None:
        self._inputs[name] = value
        if not self._stepping:
            self._start_values_changed()  # the inputs at the start time are the core's initial base

    def _start_values_changed(self) -> None:
        self._stale, self._outputs = True, None

    def _read_outputs(self) -> list:
        sim = self._core()
        if sim is None:
            return list(_NO_OUTPUTS)
        view = CoreView(sim)
        self._outputs = [read(view) for read in _READERS]
        return self._outputs

    # -- FMI life cycle ---------------------------------------------------------------------------

    def _core(self) -> Optional[Simulator]:
        """The core at the present time; before stepping, rebuilt from the start values set."""
        if self._stale and not self._stepping:
            self._stale, self._outputs = False, None
            self._sim, self._fault = None, self._bad_inputs()
            if self._fault is not None:
                return None
            try:
                params = Parameters(**self._values)
                self._sim = Simulator(params, y0=self._inputs["base_displacement"],
                                      v0=self._inputs["base_velocity"], t0=self._start_time, log_limit=0)
            except Exception as error:  # noqa: BLE001 - reported through FMI, never raised
                self._fault = f"invalid start values: {error}"
        return self._sim

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        self._start_time = float(start_time)
        self._start_values_changed()

    def exit_initialization_mode(self):
        self._core()
        self._stepping = True
        if self._fault is not None:
            self.log(self._fault, Fmi2Status.error)

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._fault is not None:
            return self._fail(self._fault)
        sim = self._sim if self._stepping else None
        if sim is None:
            return self._fail("do_step is only allowed after fmi2ExitInitializationMode")
        if not (step_size > 0.0 and math.isfinite(step_size)):
            return self._fail(f"communication step size = {step_size!r} s must be finite and > 0")
        longest = sim.longest_bracket
        if step_size > MAX_BRACKETS_PER_STEP * longest:
            return self._fail(f"communication step size = {step_size!r} s needs at least {step_size / longest:.3g} "
                              f"brackets of the integrator (the longest is {longest:.3g} s); at most "
                              f"{MAX_BRACKETS_PER_STEP:g} are allowed in one step: use shorter steps")
        t = sim.t
        if not abs(current_time - t) <= 1e-12 * max(1.0, abs(t)):
            return self._fail(f"the step starts at t = {current_time!r} s but the FMU is at t = {t!r} s; "
                              "a step must continue from the end of the previous one")
        inputs = self._inputs
        y, v = inputs["base_displacement"], inputs["base_velocity"]
        if not (math.isfinite(y) and math.isfinite(v)):
            return self._fail(f"step from t = {current_time!r} s refused: {self._bad_inputs()}")
        self._outputs = None
        try:
            sim.advance(_step_end(t, current_time, step_size), y, v)
        except Exception as error:  # noqa: BLE001 - reported through FMI, never raised
            return self._fail(f"step from t = {current_time!r} s by {step_size!r} s rejected: {error}")
        return True

    def _bad_inputs(self) -> Optional[str]:
        bad = [f"{name} = {value!r}" for name, value in self._inputs.items() if not math.isfinite(value)]
        return f"input {', '.join(bad)} is not finite" if bad else None

    def _fail(self, message: str) -> bool:
        self.log(message, Fmi2Status.error)
        return False

    # -- FMU state: the values set, the flags and the core's full snapshot, JSON-safe -------------

    def _get_fmu_state(self) -> dict:
        core = self._sim.snapshot() if self._sim is not None and not self._stale else None
        return copy.deepcopy({"values": self._values, "inputs": self._inputs,
                              "start_time": self._start_time, "stepping": self._stepping,
                              "fault": self._fault, "core": core})

    def _set_fmu_state(self, state: dict) -> None:
        state = copy.deepcopy(state)  # the host may set the same state again later
        self._values, self._inputs = state["values"], state["inputs"]
        self._start_time, self._stepping = state["start_time"], state["stepping"]
        self._fault, self._sim, self._stale, self._outputs = state["fault"], None, True, None
        if state["core"] is not None:
            self._sim = Simulator.restore(Parameters(**self._values), state["core"], log_limit=0)
            self._stale = False
