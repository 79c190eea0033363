"""The damper as a co-simulation FMU, whatever the FMI version: start values, the core, steps,
the FMU state.

:class:`CoSimulation` holds everything the FMI 2.0 and FMI 3.0 co-simulation slaves share, so
that both give the same bits at the same communication points; each slave only maps its FMI
version's calls onto it (:mod:`piezo_fmu.fmi.fmi2`, :mod:`piezo_fmu.fmi.fmi3`). The variables
are those of :data:`piezo_fmu.fmi.variables.VARIABLES`, by value reference.
"""

from __future__ import annotations

import copy
import math
from typing import Callable, Optional

from piezo_fmu import Parameters, Simulator
from piezo_fmu.fmi.variables import INPUTS, OUTPUTS, VARIABLES, Variable


class CoreView:
    """The core read at one instant, each aggregate built once for all the outputs."""

    __slots__ = ("sim", "state", "metrics", "energy")

    def __init__(self, sim: Simulator):
        self.sim, self.state, self.metrics, self.energy = sim, sim.state, sim.metrics, sim.energy


_READERS = tuple(spec.read for spec in OUTPUTS)
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


class CoSimulation:
    """One co-simulation instance of the damper.

    Parameters
    ----------
    log_error : callable
        Takes the message of every refused call or value (it names the variable, the value and
        the allowed range); the slave passes it to the host's logger with the error status.
    """

    def __init__(self, log_error: Callable[[str], None]):
        self._log_error = log_error
        self._values = {spec.name: spec.start for spec in VARIABLES if spec.causality == "parameter"}
        self._inputs = {spec.name: spec.start for spec in INPUTS}
        self._start_time = 0.0
        self._sim: Optional[Simulator] = None
        self._stale = True  # start values changed since the core was built
        self._stepping = False  # past ExitInitializationMode
        self._fault: Optional[str] = None  # why every further step must fail
        self._outputs: Optional[list] = None  # output values at the present instant, once read
        #: The getters and setters (None: not settable) by value reference.
        self.getters, self.setters = zip(*(self._access(spec) for spec in VARIABLES))

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

    def set(self, vrs, values) -> None:
        """Set the variables ``vrs`` (value references, already checked for their type)."""
        for vr, value in zip(vrs, values):
            setter = self.setters[vr]
            if setter is None:
                raise TypeError(f"variable {VARIABLES[vr].name} (valueReference={vr}, causality "
                                f"{VARIABLES[vr].causality}) cannot be set")
            setter(value)

    def _set_parameter(self, name: str, value) -> None:
        if self._stepping:
            if value == self._values[name]:
                return  # hosts that set every start value again change nothing
            self._fault = f"parameter {name} is fixed: it cannot be set to {value!r} after initialization"
            self._log_error(self._fault)
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

    # -- life cycle -------------------------------------------------------------------------------

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

    def setup(self, start_time: float) -> None:
        """The experiment starts at ``start_time`` (s)."""
        self._start_time = float(start_time)
        self._start_values_changed()

    def exit_initialization(self) -> None:
        self._core()
        self._stepping = True
        if self._fault is not None:
            self._log_error(self._fault)

    def step(self, current_time: float, step_size: float) -> bool:
        """One communication step; False (and a logged message) when it is refused."""
        if self._fault is not None:
            return self._fail(self._fault)
        sim = self._sim if self._stepping else None
        if sim is None:
            return self._fail("a step is only allowed after ExitInitializationMode")
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
        self._log_error(message)
        return False

    # -- FMU state: the values set, the flags and the core's full snapshot, JSON-safe -------------

    def get_state(self) -> dict:
        core = self._sim.snapshot() if self._sim is not None and not self._stale else None
        return copy.deepcopy({"values": self._values, "inputs": self._inputs,
                              "start_time": self._start_time, "stepping": self._stepping,
                              "fault": self._fault, "core": core})

    def set_state(self, state: dict) -> None:
        state = copy.deepcopy(state)  # the host may set the same state again later
        self._values, self._inputs = state["values"], state["inputs"]
        self._start_time, self._stepping = state["start_time"], state["stepping"]
        self._fault, self._sim, self._stale, self._outputs = state["fault"], None, True, None
        if state["core"] is not None:
            self._sim = Simulator.restore(Parameters(**self._values), state["core"], log_limit=0)
            self._stale = False
