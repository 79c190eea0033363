"""The FMI 3.0 benchmark's floor: the piezo FMU's own FMI 3.0 slave with the core taken out.

As ``null_slave.py`` is for FMI 2.0: :class:`piezo_fmu.fmi.fmi3.PiezoImpactDamper3`, its values
read and written exactly as the piezo FMU does, but ``do_step`` does no work and the outputs are
never updated from a core. Inside its FMU it imports the piezo slave (``piezo_fmu_slave3``).
"""

from pythonfmu3 import Fmi3SlaveBase

from no_core import NoCore
from piezo_fmu_slave3 import PiezoImpactDamper3


class PiezoImpactDamperFloor3(PiezoImpactDamper3, Fmi3SlaveBase):  # Fmi3SlaveBase named: pythonfmu3 finds the class by it
    """Same variables as PiezoImpactDamper3; no physics, no work."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._cosim = NoCore(self._cosim._log_error)
