"""piezo-fmu: the piezo-impact damper of Afsharfard and Farshidianfar (2014).

The simulation core (parameters, barrier equivalents, exact event-driven integration,
metrics) is plain Python and numpy; it knows nothing of FMI.
"""

from .barrier import Barrier, derive_barrier
from .parameters import DERIVED, EXPLICIT, Parameters, parameter_info

__all__ = ["Barrier", "DERIVED", "EXPLICIT", "Parameters", "derive_barrier", "parameter_info"]
