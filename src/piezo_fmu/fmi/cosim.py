"""The damper as a co-simulation FMU, whatever the FMI version: start values, the core, steps,
the FMU state.

:class:`CoSimulation` holds everything the FMI 2.0 and FMI 3.0 co-simulation slaves share, so
that both give the same bits at the same communication points; each slave only maps its FMI
version's calls onto it (:mod:`piezo_fmu.fmi.fmi2`, :mod:`piezo_fmu.fmi.fmi3`). The variables
are those of :data:`piezo_fmu.fmi.variables.VARIABLES`, by value reference.
"""

from __future__ import annotations

import copy
import functools
import math
from math import isfinite
from typing import Callable, Optional

from piezo_fmu import Parameters, Simulator, parameter_info
from piezo_fmu.solver import ENERGY_READINGS, READINGS
from piezo_fmu.fmi.clock import continues, step_end
from piezo_fmu.fmi.variables import BY_NAME, VARIABLES


#: Brackets one communication step may need at the least (a few minutes of CPU): a longer step is
#: refused at once rather than left to run for hours in the host.
MAX_BRACKETS_PER_STEP = 1e7
#: Value references of the parameters, the inputs, the outputs and the calculated parameters.
_BY_CAUSALITY = {causality: tuple(vr for vr, spec in enumerate(VARIABLES) if spec.causality == causality)
                 for causality in ("parameter", "input", "output", "calculatedParameter")}


def _runs(outputs) -> tuple:
    """``(first vr, end vr, first reading, end reading)`` of the stretches where consecutive
    outputs are consecutive readings (:data:`piezo_fmu.solver.READINGS`): each is one slice copy."""
    runs = []
    for vr in outputs:
        i = READINGS.index(VARIABLES[vr].name)
        if runs and runs[-1][1] == vr and runs[-1][3] == i:
            runs[-1][1], runs[-1][3] = vr + 1, i + 1
        else:
            runs.append([vr, vr + 1, i, i + 1])
    return tuple(tuple(run) for run in runs)


_RUNS = _runs(_BY_CAUSALITY["output"])
#: The outputs that are 0 while the core's reading is NaN (a metric not defined yet).
_UNDEFINED_IS_ZERO = tuple(vr for vr in _BY_CAUSALITY["output"] if VARIABLES[vr].undefined_is_zero)
#: The outputs of the energy ledger's quadratures, and what a read of none of them brings up to date
#: (the core's ``reading_values(energy=False)``): the other outputs, and the calculated parameters.
_ENERGY = frozenset(BY_NAME[name] for name in ENERGY_READINGS)
_MOTION_RUNS = _runs(vr for vr in _BY_CAUSALITY["output"] if vr not in _ENERGY)
#: How much of the outputs in ``CoSimulation.now`` is of the present instant: none, all but the
#: energy ledger's, or all.
STALE, MOTION, ALL = range(3)
_Y, _V = BY_NAME["base_displacement"], BY_NAME["base_velocity"]
#: The variables whose values come from the core: reading one brings them up to date.
_FROM_CORE = frozenset(_BY_CAUSALITY["output"] + _BY_CAUSALITY["calculatedParameter"])
#: Output and calculated values while there is no core (bad start values): NaN, and 0 for the Integer.
_NO_CORE = tuple((vr, 0 if VARIABLES[vr].type == "Integer" else math.nan)
                 for vr in _BY_CAUSALITY["output"] + _BY_CAUSALITY["calculatedParameter"])


#: The table's types as each FMI version names them.
TYPE_NAMES = {2: {"Real": "Real", "Integer": "Integer"}, 3: {"Real": "Float64", "Integer": "Int32"}}


def type_problem(vrs, kind: str, names: dict, variables=VARIABLES) -> Optional[str]:
    """Why ``vrs`` are not all value references of ``variables`` (the table by default) of the
    table's type ``kind`` ("Real", "Integer", or the name of a type it has none of), or None;
    types named as ``names`` (:data:`TYPE_NAMES`) says."""
    for vr in vrs:
        if not 0 <= vr < len(variables):
            return f"no variable has valueReference={vr}"
        if variables[vr].type != kind:
            return (f"variable {variables[vr].name} (valueReference={vr}) is of type {names[variables[vr].type]}, "
                    f"not {names.get(kind, kind)}")
    return None


def no_values(vrs, kind: str) -> list:
    """What a refused get returns: NaN for the table's Real variables, 0 for any other type."""
    return [math.nan if kind == "Real" else 0] * len(vrs)


def _allowed_ranges() -> dict:
    """The allowed range of each Real parameter and input, by value reference, with its unit."""
    bounds = parameter_info()
    return {vr: f"{bounds[spec.name]['bound'].describe() if spec.name in bounds else '(-inf, inf)'} {spec.unit}"
            for vr, spec in enumerate(VARIABLES) if spec.causality in ("parameter", "input") and spec.type == "Real"}


_ALLOWED = _allowed_ranges()


def publish(now: list, readings, energy: bool = True) -> None:
    """Write ``readings`` (values in the order of :data:`piezo_fmu.solver.READINGS`) into the outputs
    of ``now`` (values by value reference): each output is the reading of its name, 0 where it is
    undefined (NaN) and the table says so; with ``energy`` False, all but the outputs of
    :data:`piezo_fmu.solver.ENERGY_READINGS` (left as they were, not current: a read of one of
    them publishes them all first, ``CoSimulation.get``). Every interface serves its outputs
    through this."""
    for first, end, begin, stop in _RUNS if energy else _MOTION_RUNS:
        now[first:end] = readings[begin:stop]
    for vr in _UNDEFINED_IS_ZERO:
        if now[vr] != now[vr]:
            now[vr] = 0.0


def guarded(fallback: Callable):
    """Wrap a slave's FMI entry point so that no exception ever leaves it.

    pythonfmu's and pythonfmu3's binaries turn an exception into the fatal status and then release
    Python objects they still use, so that a later exception or garbage collection in the process
    crashes the host. An unexpected exception is therefore logged through the slave's
    ``_log_fatal`` (the fatal status: the instance must not be used again) and ``fallback(*args)``
    is returned instead.
    """
    def wrap(method):
        @functools.wraps(method)
        def entry_point(self, *args):
            try:
                return method(self, *args)
            except Exception as error:  # noqa: BLE001 - an exception must not reach the binary
                self._log_fatal(f"{method.__name__}: unexpected {type(error).__name__}: {error}")
                return fallback(*args)
        return entry_point
    return wrap


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
        #: Every variable's value by value reference; outputs and calculated parameters are brought
        #: up to date (``_update``) when read.
        self.now = [spec.start if spec.start is not None else 0 if spec.type == "Integer" else math.nan
                    for spec in VARIABLES]
        self._fresh = STALE  # how much of the outputs in ``now`` is of the present instant
        self._start_time = 0.0
        self._sim: Optional[Simulator] = None
        self._stale = True  # start values changed since the core was built
        self._stepping = False  # past ExitInitializationMode
        self._first_step = False  # no step yet since ExitInitializationMode (FMI 3.0: start_at)
        self._fault: Optional[str] = None  # why every further step must fail

    def get(self, vrs) -> list:
        """The values of the variables ``vrs`` (value references, already checked for their type).
        The energy ledger's outputs are brought up to date only when some of them are read (the
        values are the same either way: ``Simulator.reading_values``)."""
        if self._fresh != ALL and not _FROM_CORE.isdisjoint(vrs):
            if not _ENERGY.isdisjoint(vrs):
                self._update(ALL)
            elif self._fresh == STALE:
                self._update(MOTION)
        now = self.now
        return [now[vr] for vr in vrs]

    def set(self, vrs, values) -> None:
        """Set the table's variables ``vrs`` (value references, already checked for their type). A
        variable that cannot be set, a non-finite Real, or a parameter after initialization is
        refused: logged, and not set."""
        for vr, value in zip(vrs, values):
            spec = VARIABLES[vr]
            if spec.causality not in ("parameter", "input"):
                self._log_error(f"set: variable {spec.name} (valueReference={vr}, causality {spec.causality}) "
                                "cannot be set")
            elif spec.type == "Real" and not isfinite(value):
                self._log_error(f"{spec.name} = {value!r} is not finite; allowed range {_ALLOWED[vr]}")
            elif spec.causality == "parameter":
                self._set_parameter(vr, value)
            else:
                self.now[vr] = value
                if not self._stepping:
                    self._start_values_changed()  # the inputs at the start time are the core's initial base

    def _set_parameter(self, vr: int, value) -> None:
        if self._stepping:
            if value == self.now[vr]:
                return  # hosts that set every start value again change nothing
            self._fault = f"parameter {VARIABLES[vr].name} is fixed: it cannot be set to {value!r} after initialization"
            self._log_error(self._fault)
            return
        self.now[vr] = value
        self._start_values_changed()

    def _start_values_changed(self) -> None:
        self._stale, self._fresh = True, STALE

    def _update(self, level: int) -> None:
        """Bring the outputs (and, with a new core, the calculated parameters) in ``now`` up to date:
        all of them (``level`` :data:`ALL`) or all but the energy ledger's (:data:`MOTION`)."""
        sim = self._sim if self._stepping or not self._stale else self._core()
        now = self.now
        if sim is None:
            for vr, value in _NO_CORE:
                now[vr] = value
            level = ALL
        else:
            energy = level == ALL
            publish(now, sim.reading_values(energy), energy)
        self._fresh = level

    # -- life cycle -------------------------------------------------------------------------------

    def _parameters(self) -> dict:
        now = self.now
        return {VARIABLES[vr].name: now[vr] for vr in _BY_CAUSALITY["parameter"]}

    def _inputs(self) -> dict:
        now = self.now
        return {VARIABLES[vr].name: now[vr] for vr in _BY_CAUSALITY["input"]}

    def _core(self) -> Optional[Simulator]:
        """The core at the present time; before stepping, rebuilt from the start values set."""
        if self._stale and not self._stepping:
            self._stale, self._fresh = False, STALE
            self._sim, self._fault = None, self._bad_inputs()
            if self._fault is not None:
                return None
            try:
                params = Parameters(**self._parameters())
                self._sim = Simulator(params, y0=self.now[_Y], v0=self.now[_V], t0=self._start_time, log_limit=0)
            except Exception as error:  # noqa: BLE001 - reported through FMI, never raised
                self._fault = f"invalid start values: {error}"
            else:
                self._core_built()
        return self._sim

    @property
    def fault(self) -> Optional[str]:
        """Why the instance cannot go on (bad start values, a fixed parameter set later), or None."""
        self._core()
        return self._fault

    def simulator(self) -> Optional[Simulator]:
        """The core of the start values set, where it stands (None when they are refused)."""
        return self._core()

    def _core_built(self) -> None:
        """The calculated parameters of a new core, and the longest step it takes."""
        sim = self._sim
        for vr in _BY_CAUSALITY["calculatedParameter"]:
            self.now[vr] = VARIABLES[vr].read(sim.damper)
        self._max_step = MAX_BRACKETS_PER_STEP * sim.longest_bracket

    def setup(self, start_time: float) -> None:
        """The experiment starts at ``start_time`` (s)."""
        self._start_time = float(start_time)
        self._start_values_changed()

    @property
    def time(self) -> float:
        """The FMU's time (s): where the core stands, or the start time."""
        return self._sim.t if self._sim is not None and not self._stale else self._start_time

    def start_at(self, t0: float) -> None:
        """Start at ``t0`` (s) instead of the start time set, at the first step after initialization
        (pythonfmu3 does not pass FMI 3.0's start time on: a co-simulation learns it from its first
        step)."""
        if self._first_step:
            self._first_step = False
            if t0 != self._start_time and self._sim is not None:
                self._start_time, self._stepping = float(t0), False
                self._start_values_changed()
                self._core()
                self._stepping = True

    def exit_initialization(self) -> None:
        self._core()
        self._stepping, self._first_step = True, True
        if self._fault is not None:
            self._log_error(self._fault)

    def step(self, current_time: float, step_size: float) -> bool:
        """One communication step; False (and a logged message) when it is refused."""
        if self._fault is not None:
            return self._fail(self._fault)
        sim = self._sim if self._stepping else None
        if sim is None:
            return self._fail("a step is only allowed after ExitInitializationMode")
        if not (0.0 < step_size <= self._max_step):
            return self._fail(self._bad_step_size(step_size))
        t = sim.t
        if not continues(t, current_time):
            return self._fail(f"the step starts at t = {current_time!r} s but the FMU is at t = {t!r} s; "
                              "a step must continue from the end of the previous one")
        now = self.now
        y, v = now[_Y], now[_V]
        if not (isfinite(y) and isfinite(v)):
            return self._fail(f"step from t = {current_time!r} s refused: {self._bad_inputs()}")
        try:
            end = step_end(t, current_time, step_size)
            if end == t:
                return True  # shorter than the clock's tolerance, and started before the FMU's time
            self._fresh = STALE
            sim.advance(end, y, v)
        except Exception as error:  # noqa: BLE001 - reported through FMI, never raised
            return self._fail(f"step from t = {current_time!r} s by {step_size!r} s rejected: {error}")
        return True

    def _bad_step_size(self, step_size: float) -> str:
        if not (step_size > 0.0 and math.isfinite(step_size)):
            return f"communication step size = {step_size!r} s must be finite and > 0"
        longest = self._sim.longest_bracket
        return (f"communication step size = {step_size!r} s needs at least {step_size / longest:.3g} "
                f"brackets of the integrator (the longest is {longest:.3g} s); at most "
                f"{MAX_BRACKETS_PER_STEP:g} are allowed in one step: use shorter steps")

    def _bad_inputs(self) -> Optional[str]:
        bad = [f"{name} = {value!r}" for name, value in self._inputs().items() if not math.isfinite(value)]
        return f"input {', '.join(bad)} is not finite" if bad else None

    def _fail(self, message: str) -> bool:
        self._log_error(message)
        return False

    # -- FMU state: the values set, the flags and the core's full snapshot, JSON-safe -------------

    def get_state(self) -> dict:
        core = self._sim.snapshot() if self._sim is not None and not self._stale else None
        return copy.deepcopy({"values": self._parameters(), "inputs": self._inputs(),
                              "start_time": self._start_time, "stepping": self._stepping,
                              "fault": self._fault, "core": core})

    def set_state(self, state: dict) -> None:
        state = copy.deepcopy(state)  # the host may set the same state again later
        self._first_step = False
        for name, value in {**state["values"], **state["inputs"]}.items():
            self.now[BY_NAME[name]] = value
        self._start_time, self._stepping = state["start_time"], state["stepping"]
        self._fault, self._sim, self._stale, self._fresh = state["fault"], None, True, STALE
        if state["core"] is not None:
            self._sim = Simulator.restore(Parameters(**self._parameters()), state["core"], log_limit=0)
            self._stale = False
            self._core_built()
