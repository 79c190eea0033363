"""The FMI 3.0 slave of the piezo-impact damper (pythonfmu3): co-simulation.

A thin adapter, as :mod:`piezo_fmu.fmi.fmi2` is for FMI 2.0: the calls of pythonfmu3 are mapped
onto :class:`piezo_fmu.fmi.cosim.CoSimulation`, so that the FMI 3.0 co-simulation gives the FMI 2.0
one's bits at the same communication points, and the variables are those of
:data:`piezo_fmu.fmi.variables.VARIABLES` under the same value references (Real as Float64,
Integer as Int32), followed by the independent variable ``time``. :mod:`piezo_fmu.fmi.build`
turns this script into ``fmus/PiezoImpactDamper3.fmu`` and completes its modelDescription.

Inside the FMU this file is the top-level module ``piezo_fmu_slave3``; imports are absolute.

Nothing escapes as an exception: pythonfmu3's binary turns one into fmi3Fatal and releases
objects it still uses, which can crash the host later. A refused value or call is logged with
the error status (naming the variable, the value and the allowed range) and a refused step
returns fmi3Error; anything unexpected is logged with the fatal status.
"""

from __future__ import annotations

import math
from typing import Dict, List

from pythonfmu3 import DefaultExperiment, Fmi3Causality, Fmi3SlaveBase, Fmi3Status, Fmi3StepResult, Fmi3Variability
from pythonfmu3 import CoSimulation as CoSimulationInterface
from pythonfmu3 import Float64, Int32
from pythonfmu3.enums import Fmi3Initial

from piezo_fmu.fmi.cosim import CoSimulation, guarded
from piezo_fmu.fmi.variables import REFERENCES, VARIABILITY, VARIABLES, Variable

#: FMI 3.0 types of the table's FMI 2.0 types.
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32"}
#: The value reference of the independent variable, after the table.
TIME = len(VARIABLES)

def model_variable(spec: Variable, getter, setter=None):
    """The pythonfmu3 variable for one row of the table (units, bounds and starts are written by
    the build, from the same table)."""
    kind = Int32 if spec.type == "Integer" else Float64
    initial = Fmi3Initial.exact if spec.causality == "parameter" else None
    return kind(spec.name, causality=Fmi3Causality[spec.causality],
                variability=Fmi3Variability[VARIABILITY[spec.causality, spec.type]],
                initial=initial, description=spec.description, getter=getter, setter=setter)


def type_problem(vrs, kind: str) -> str | None:
    """Why ``vrs`` are not all variables of the FMI 2.0 type ``kind`` of the table, or None."""
    if REFERENCES.get(kind, frozenset()).issuperset(vrs):
        return None
    for vr in vrs:
        if not 0 <= vr < len(VARIABLES):
            return f"no variable has valueReference={vr}"
        if VARIABLES[vr].type != kind:
            return (f"variable {VARIABLES[vr].name} (valueReference={vr}) is of type "
                    f"{FMI3_TYPES.get(VARIABLES[vr].type)}, not {FMI3_TYPES.get(kind, kind)}")
    return None


class PiezoImpactDamper3(Fmi3SlaveBase, CoSimulationInterface):
    """Piezo-impact damper (Afsharfard and Farshidianfar 2014): main mass, impact mass and two
    piezoelectric cantilever barriers, driven by base motion; exact event-driven core."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "piezo-fmu"
        self.description = ("Piezo-impact damper (Afsharfard and Farshidianfar 2014) driven by base motion; "
                            "exact event-driven core. Needs Python 3 with numpy.")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)
        self.time = 0.0  # pythonfmu3 requires it; the co-simulation's own time is self._cosim.time
        self._cosim = CoSimulation(self._refuse)

    def to_xml(self, model_options: Dict[str, str] = dict()):  # noqa: B006 - pythonfmu3's signature
        # pythonfmu3's variable objects are made only for the model description.
        if not self.vars:
            cosim = self._cosim
            for vr, spec in enumerate(VARIABLES):
                setter = (lambda value, vr=vr: cosim.set([vr], [value])) if spec.causality in ("parameter", "input") else None
                self.register_variable(model_variable(spec, lambda vr=vr: cosim.get([vr])[0], setter), nested=False)
            self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                           variability=Fmi3Variability.continuous, description="Simulation time",
                                           getter=lambda: self._cosim.time), nested=False)
        return super().to_xml(model_options)

    # -- errors: logged, never raised ------------------------------------------------------------

    def _refuse(self, message: str) -> None:
        self.log(message, Fmi3Status.error)

    def _log_fatal(self, message: str) -> None:
        self.log(message, Fmi3Status.fatal)

    def _values(self, vrs: List[int], kind: str) -> list:
        problem = type_problem([vr for vr in vrs if vr != TIME], kind) if kind else "no variable has this type"
        if problem is not None:
            self._refuse(f"get: {problem}")
            return _no_values(vrs, kind)
        if TIME in vrs:
            return [self._cosim.time if vr == TIME else self._cosim.get([vr])[0] for vr in vrs]
        return self._cosim.get(vrs)

    def _assign(self, vrs: List[int], values: list, kind: str) -> None:
        problem = type_problem(vrs, kind) if kind else "no variable has this type"
        if problem is None:
            fixed = [vr for vr in vrs if VARIABLES[vr].causality not in ("parameter", "input")]
            if fixed:
                vr = fixed[0]
                problem = (f"variable {VARIABLES[vr].name} (valueReference={vr}, causality {VARIABLES[vr].causality}) "
                           "cannot be set")
        if problem is not None:
            self._refuse(f"set: {problem}")
            return
        self._cosim.set(vrs, values)

    # -- values ---------------------------------------------------------------------------------

    @guarded(lambda vrs: _no_values(vrs, "Real"))
    def get_float64(self, vrs: List[int]) -> List[float]:
        return self._values(vrs, "Real")

    @guarded(lambda vrs: _no_values(vrs, "Integer"))
    def get_int32(self, vrs: List[int]) -> List[int]:
        return self._values(vrs, "Integer")

    @guarded(lambda vrs, values: None)
    def set_float64(self, vrs: List[int], values: List[float]):
        self._assign(vrs, values, "Real")

    @guarded(lambda vrs, values: None)
    def set_int32(self, vrs: List[int], values: List[int]):
        self._assign(vrs, values, "Integer")

    @guarded(lambda vrs: _no_values(vrs, ""))
    def get_int64(self, vrs):
        return self._values(vrs, "")

    @guarded(lambda vrs: _no_values(vrs, ""))
    def get_uint64(self, vrs):
        return self._values(vrs, "")

    @guarded(lambda vrs: _no_values(vrs, ""))
    def get_boolean(self, vrs):
        return self._values(vrs, "")

    @guarded(lambda vrs: _no_values(vrs, ""))
    def get_string(self, vrs):
        return self._values(vrs, "")

    @guarded(lambda vrs, values: None)
    def set_int64(self, vrs, values):
        self._assign(vrs, values, "")

    @guarded(lambda vrs, values: None)
    def set_uint64(self, vrs, values):
        self._assign(vrs, values, "")

    @guarded(lambda vrs, values: None)
    def set_boolean(self, vrs, values):
        self._assign(vrs, values, "")

    @guarded(lambda vrs, values: None)
    def set_string(self, vrs, values):
        self._assign(vrs, values, "")

    # -- life cycle -----------------------------------------------------------------------------

    @guarded(lambda: None)
    def exit_initialization_mode(self):
        self._cosim.exit_initialization()

    @guarded(lambda current_time, step_size: Fmi3StepResult(status=Fmi3Status.fatal))
    def do_step(self, current_time: float, step_size: float) -> Fmi3StepResult:
        self._cosim.start_at(current_time)
        if not self._cosim.step(current_time, step_size):
            return Fmi3StepResult(status=Fmi3Status.error)
        return Fmi3StepResult()

    @guarded(lambda: None)
    def _get_fmu_state(self) -> dict:
        return self._cosim.get_state()

    @guarded(lambda state: None)
    def _set_fmu_state(self, state: dict) -> None:
        self._cosim.set_state(state)


def _no_values(vrs, kind: str) -> list:
    """What a refused get returns: NaN for Float64, 0 for the other types."""
    return [math.nan if kind == "Real" else 0] * len(vrs)
