"""The benchmark's floor: the piezo FMU's own FMI 2.0 slave with the core taken out.

It is :class:`piezo_fmu.fmi.fmi2.PiezoImpactDamper` (the same variables, type checks and
value-reference tables), reading and writing its values exactly as the piezo FMU does, but
``do_step`` does no work and the outputs are never updated from a core (``no_core.py``). Timing
the piezo FMU against it through fmpy isolates what the core and its readings cost on top of FMI,
pythonfmu and fmpy. Inside its FMU it imports the piezo slave (``piezo_fmu_slave``).
"""

from no_core import NoCore
from piezo_fmu_slave import PiezoImpactDamper


class PiezoImpactDamperFloor(PiezoImpactDamper):
    """Same variables as PiezoImpactDamper; no physics, no work."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._cosim = NoCore(self._cosim._log_error)
