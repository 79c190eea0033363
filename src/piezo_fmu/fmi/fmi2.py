"""The FMI 2.0 co-simulation slave of the piezo-impact damper (pythonfmu).

A thin adapter: pythonfmu's calls are mapped onto :class:`piezo_fmu.fmi.cosim.CoSimulation`, and
the variables are those of :data:`piezo_fmu.fmi.variables.VARIABLES`; there is no physics here.
:mod:`piezo_fmu.fmi.build` turns this script into ``fmus/PiezoImpactDamper.fmu`` and completes the
modelDescription with the units, bounds and structure the table declares.

Inside the FMU this file is the top-level module ``piezo_fmu_slave`` and imports the core from
the ``piezo_fmu`` package bundled beside it in ``resources/``. Imports are absolute for that
reason. The module holds no mutable state: every instance keeps its own.

Errors never escape as exceptions (pythonfmu turns those into ``fmi2Fatal``). A bad parameter, a
non-finite input, a non-positive step or a step that does not start at the current time is logged
with ``fmi2Error`` and the step returns ``fmi2Discard``; the instance stays usable (set finite
inputs and step again, or reset it).
"""

from __future__ import annotations

from typing import Callable, Dict, List, Optional

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from piezo_fmu.fmi.cosim import CoSimulation
from piezo_fmu.fmi.variables import KINDS, REFERENCES, VARIABILITY, VARIABLES, Variable

def scalar_variable(spec: Variable, getter: Callable, setter: Optional[Callable] = None):
    """The pythonfmu variable for one row of the table."""
    kind = Integer if spec.type == "Integer" else Real
    initial = Fmi2Initial.exact if spec.causality == "parameter" else None
    return kind(spec.name, causality=Fmi2Causality[spec.causality],
                variability=Fmi2Variability[VARIABILITY[spec.causality, spec.type]], initial=initial,
                description=spec.description, getter=getter, setter=setter)


def checked(vrs, kind: str):
    """``vrs``, each checked to be a variable of ``kind`` (as pythonfmu's own accessors do)."""
    if not REFERENCES.get(kind, frozenset()).issuperset(vrs):
        for vr in vrs:
            if not 0 <= vr < len(KINDS):
                raise KeyError(f"no variable has valueReference={vr}")
            if KINDS[vr] != kind:
                raise TypeError(f"Variable with valueReference={vr} is not of type {kind}!")
    return vrs


class PiezoImpactDamper(Fmi2Slave):
    """Piezo-impact damper (Afsharfard and Farshidianfar 2014): main mass, impact mass and two
    piezoelectric cantilever barriers, driven by base motion; exact event-driven core."""

    author = "piezo-fmu"
    description = ("Piezo-impact damper (Afsharfard and Farshidianfar 2014) driven by base motion; "
                   "exact event-driven core. Needs Python 3 with numpy.")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._cosim = CoSimulation(lambda message: self.log(message, Fmi2Status.error))

    def to_xml(self, model_options: Dict[str, str] = dict()):  # noqa: B006 - pythonfmu's signature
        # pythonfmu's variable objects are made only for the model description: every fmi2Reset
        # builds a new instance, and 54 of them cost 5% of a 2 s sweep point.
        if not self.vars:
            cosim = self._cosim
            for vr, spec in enumerate(VARIABLES):
                setter = (lambda value, vr=vr: cosim.set([vr], [value])) if spec.causality in ("parameter", "input") else None
                self.register_variable(scalar_variable(spec, lambda vr=vr: cosim.get([vr])[0], setter), nested=False)
        return super().to_xml(model_options)

    def get_real(self, vrs: List[int]) -> List[float]:
        return self._cosim.get(checked(vrs, "Real"))

    def get_integer(self, vrs: List[int]) -> List[int]:
        return self._cosim.get(checked(vrs, "Integer"))

    def set_real(self, vrs: List[int], values: List[float]):
        self._cosim.set(checked(vrs, "Real"), values)

    def set_integer(self, vrs: List[int], values: List[int]):
        self._cosim.set(checked(vrs, "Integer"), values)

    def get_boolean(self, vrs: List[int]) -> List[bool]:
        checked(vrs, "Boolean")
        return []

    def get_string(self, vrs: List[int]) -> List[str]:
        checked(vrs, "String")
        return []

    def set_boolean(self, vrs: List[int], values: List[bool]):
        checked(vrs, "Boolean")

    def set_string(self, vrs: List[int], values: List[str]):
        checked(vrs, "String")

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        self._cosim.setup(start_time)

    def exit_initialization_mode(self):
        self._cosim.exit_initialization()

    def do_step(self, current_time: float, step_size: float) -> bool:
        return self._cosim.step(current_time, step_size)

    def _get_fmu_state(self) -> dict:
        return self._cosim.get_state()

    def _set_fmu_state(self, state: dict) -> None:
        self._cosim.set_state(state)
