"""The benchmark's floor: the piezo FMU's own FMI 2.0 slave with the core taken out.

It is :class:`piezo_fmu.fmi.fmi2.PiezoImpactDamper` (the same variables, type checks and
value-reference tables), reading and writing its values exactly as the piezo FMU does, but
``do_step`` does no work and the outputs are never updated from a core. Timing the piezo FMU
against it through fmpy isolates what the core and its readings cost on top of FMI, pythonfmu and
fmpy. Inside its FMU it imports the piezo slave (``piezo_fmu_slave``) and the bundled
``piezo_fmu`` package.
"""

from piezo_fmu.fmi.cosim import CoSimulation
from piezo_fmu_slave import PiezoImpactDamper


class _NoCore(CoSimulation):
    """Values are read and written as the piezo FMU's are; no core, no steps."""

    def step(self, current_time: float, step_size: float) -> bool:
        return True

    def _update(self) -> None:
        self._current = True


class PiezoImpactDamperFloor(PiezoImpactDamper):
    """Same variables as PiezoImpactDamper; no physics, no work."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._cosim = _NoCore(self._cosim._log_error)
