"""The FMI 2.0 co-simulation slave of the piezo-impact damper (pythonfmu).

A thin adapter: pythonfmu's calls are mapped onto :class:`piezo_fmu.fmi.cosim.CoSimulation`, and
the variables are those of :data:`piezo_fmu.fmi.variables.VARIABLES`; there is no physics here.
:mod:`piezo_fmu.build` turns this script into ``fmus/PiezoImpactDamper.fmu`` and completes the
modelDescription with the units, bounds and structure the table declares.

Inside the FMU this file is the top-level module ``piezo_fmu_slave`` and imports the core from
the ``piezo_fmu`` package bundled beside it in ``resources/``. Imports are absolute for that
reason. The module holds no mutable state: every instance keeps its own.

Nothing escapes as an exception: pythonfmu's binary turns one into fmi2Fatal (and, unmended,
releases objects it still uses). A refused value or call (a wrong value reference or type, an
output set, a non-finite value, a parameter set after initialization, invalid start values at
ExitInitializationMode, a bad step size, a step that does not continue from the FMU's time, a
non-finite input) is logged with the error status, naming the variable, the value and the allowed
range; the FMU's loader (``piezo_fmu.build.loader``) returns fmi2Error from that very call, and
fmi2Reset brings the instance back. Something unexpected is logged with the fatal status.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Optional

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from piezo_fmu.fmi.cosim import TYPE_NAMES, CoSimulation, guarded, no_values, type_problem
from piezo_fmu.fmi.variables import REFERENCES, VARIABILITY, VARIABLES, Variable

_NONE = frozenset()

def scalar_variable(spec: Variable, getter: Callable, setter: Optional[Callable] = None):
    """The pythonfmu variable for one row of the table."""
    kind = Integer if spec.type == "Integer" else Real
    initial = Fmi2Initial.exact if spec.causality == "parameter" else None
    return kind(spec.name, causality=Fmi2Causality[spec.causality],
                variability=Fmi2Variability[VARIABILITY[spec.causality, spec.type]], initial=initial,
                description=spec.description, getter=getter, setter=setter)


class PiezoImpactDamper(Fmi2Slave):
    """Piezo-impact damper (Afsharfard and Farshidianfar 2014): main mass, impact mass and two
    piezoelectric cantilever barriers, driven by base motion; exact event-driven core."""

    author = "piezo-fmu"
    description = ("Piezo-impact damper (Afsharfard and Farshidianfar 2014) driven by base motion; "
                   "exact event-driven core. Needs Python 3 with numpy.")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._cosim = CoSimulation(self._refuse)

    def to_xml(self, model_options: Dict[str, str] = dict()):  # noqa: B006 - pythonfmu's signature
        # pythonfmu's variable objects are made only for the model description: every fmi2Reset
        # builds a new instance, and 54 of them cost 5% of a 2 s sweep point.
        if not self.vars:
            cosim = self._cosim
            for vr, spec in enumerate(VARIABLES):
                setter = (lambda value, vr=vr: cosim.set([vr], [value])) if spec.causality in ("parameter", "input") else None
                self.register_variable(scalar_variable(spec, lambda vr=vr: cosim.get([vr])[0], setter), nested=False)
        return super().to_xml(model_options)

    # -- errors: logged, never raised (the loader returns the logged status from the call) ---------

    def _refuse(self, message: str) -> None:
        self.log(message, Fmi2Status.error)

    def _log_fatal(self, message: str) -> None:
        self.log(message, Fmi2Status.fatal)

    # -- values -------------------------------------------------------------------------------------

    def _get(self, vrs: List[int], kind: str) -> list:
        if not REFERENCES.get(kind, _NONE).issuperset(vrs):
            self._refuse(f"get: {type_problem(vrs, kind, TYPE_NAMES[2])}")
            return no_values(vrs, kind)
        return self._cosim.get(vrs)

    def _set(self, vrs: List[int], values: list, kind: str) -> None:
        problem = type_problem(vrs, kind, TYPE_NAMES[2])
        if problem is not None:
            self._refuse(f"set: {problem}")
            return
        self._cosim.set(vrs, values)

    @guarded(lambda vrs: no_values(vrs, "Real"))
    def get_real(self, vrs: List[int]) -> List[float]:
        return self._get(vrs, "Real")

    @guarded(lambda vrs: no_values(vrs, "Integer"))
    def get_integer(self, vrs: List[int]) -> List[int]:
        return self._get(vrs, "Integer")

    @guarded(lambda vrs: no_values(vrs, "Boolean"))
    def get_boolean(self, vrs: List[int]) -> List[bool]:
        return self._get(vrs, "Boolean")

    @guarded(lambda vrs: no_values(vrs, "String"))
    def get_string(self, vrs: List[int]) -> List[str]:
        return self._get(vrs, "String")

    @guarded(lambda vrs, values: None)
    def set_real(self, vrs: List[int], values: List[float]):
        self._set(vrs, values, "Real")

    @guarded(lambda vrs, values: None)
    def set_integer(self, vrs: List[int], values: List[int]):
        self._set(vrs, values, "Integer")

    @guarded(lambda vrs, values: None)
    def set_boolean(self, vrs: List[int], values: List[bool]):
        self._set(vrs, values, "Boolean")

    @guarded(lambda vrs, values: None)
    def set_string(self, vrs: List[int], values: List[str]):
        self._set(vrs, values, "String")

    # -- life cycle -----------------------------------------------------------------------------------

    @guarded(lambda start_time, stop_time=None, tolerance=None: None)
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        self._cosim.setup(start_time)

    @guarded(lambda: None)
    def exit_initialization_mode(self):
        self._cosim.exit_initialization()

    @guarded(lambda current_time, step_size: False)
    def do_step(self, current_time: float, step_size: float) -> bool:
        return self._cosim.step(current_time, step_size)

    @guarded(lambda: None)
    def _get_fmu_state(self) -> dict:
        return self._cosim.get_state()

    @guarded(lambda state: None)
    def _set_fmu_state(self, state: dict) -> None:
        self._cosim.set_state(state)
