"""The benchmark's floor: a pythonfmu slave with the piezo FMU's variables that does no work.

It registers the same table (names, types, causalities, start values) as
``piezo_fmu.fmi.fmi2`` and reads and writes plain values; ``do_step`` returns at once. Timing
the piezo FMU against it through fmpy isolates what the core costs on top of FMI, pythonfmu and
fmpy. Inside its FMU it imports the table from the bundled ``piezo_fmu`` package and the piezo
slave (``piezo_fmu_slave``).
"""

from pythonfmu import DefaultExperiment, Fmi2Slave

from piezo_fmu_slave import VARIABLES, scalar_variable


class PiezoImpactDamperFloor(Fmi2Slave):
    """Same variables as PiezoImpactDamper; no physics, no work."""

    default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-4)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._values = {spec.name: spec.start if spec.start is not None else 0 for spec in VARIABLES}
        for spec in VARIABLES:
            self.register_variable(self._variable(spec.name, spec), nested=False)

    def _variable(self, name, spec):
        def setter(value):
            self._values[name] = value
        return scalar_variable(spec, lambda: self._values[name],
                               None if spec.causality == "output" else setter)

    def do_step(self, current_time: float, step_size: float) -> bool:
        return True
