"""The exact event-driven solver of the damper model (:mod:`piezo_fmu.model`).

- :mod:`.propagation`: the exact flow of a linear phase over brackets (Taylor series to rounding);
- :mod:`.roots`: every sign change of a bracket polynomial, isolated in the Bernstein basis;
- :mod:`.brackets`: a bracket's trajectory and the events located on it;
- :mod:`.circuit`: the patch circuits, exact on every bracket;
- :mod:`.ledger`: the energy ledger, integrated exactly;
- :mod:`.metrics`: the running metrics (eqs. 29-31);
- :mod:`.simulator`: the advance loop, the switches, and the public :class:`Simulator`;
- :mod:`.snapshot`: a simulator's full state, saved and restored.
"""

from .ledger import EnergyLedger
from .metrics import Metrics, perfectibility
from .records import Impact, State
from .simulator import ENERGY_READINGS, READINGS, Simulator

__all__ = ["ENERGY_READINGS", "EnergyLedger", "Impact", "Metrics", "READINGS", "Simulator", "State", "perfectibility"]
