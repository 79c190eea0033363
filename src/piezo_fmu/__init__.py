"""piezo-fmu: the piezo-impact damper of Afsharfard and Farshidianfar (2014).

The simulation core (parameters, barrier equivalents, exact event-driven integration,
metrics) is plain Python and numpy; it knows nothing of FMI.
"""

from .barrier import Barrier, derive_barrier
from .metrics import Metrics, perfectibility
from .parameters import CIRCUIT, COUPLED, DERIVED, EXPLICIT, QUASI_STATIC, Parameters, parameter_info
from .simulator import EnergyLedger, Impact, Simulator, State

__all__ = [
    "Barrier", "CIRCUIT", "COUPLED", "DERIVED", "EXPLICIT", "QUASI_STATIC", "EnergyLedger", "Impact", "Metrics", "Parameters", "Simulator",
    "State", "derive_barrier", "parameter_info", "perfectibility",
]
