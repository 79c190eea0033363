"""piezo-fmu: the piezo-impact damper of Afsharfard and Farshidianfar (2014).

The package is layered, and imports run one way:

- :mod:`piezo_fmu.fmi`: the FMI interfaces (one variable table, one adapter per interface, the
  build of the FMUs);
- :mod:`piezo_fmu.solver`: the exact event-driven integration of the model;
- :mod:`piezo_fmu.model`: the physics only (parameters, barrier equivalents, phase matrices,
  event functions, switch rules, energies, voltage models).

The model and the solver are plain Python and numpy and know nothing of FMI.
"""

__version__ = "0.2.0"

from .model import (CIRCUIT, COUPLED, DERIVED, EXPLICIT, QUASI_STATIC, Barrier, Damper, Parameters, derive_barrier,
                    parameter_info)
from .solver import EnergyLedger, Impact, Metrics, Simulator, State, perfectibility

__all__ = [
    "Barrier", "CIRCUIT", "COUPLED", "DERIVED", "Damper", "EXPLICIT", "EnergyLedger", "Impact", "Metrics", "Parameters",
    "QUASI_STATIC", "Simulator", "State", "derive_barrier", "parameter_info", "perfectibility",
]
