"""The physics of the piezo-impact damper, and nothing else (docs/model.md).

- :mod:`.parameters`: the parameters (SI, the paper's symbols) and their validation;
- :mod:`.barrier`: the barrier beam's tip equivalents and the patch constants (eqs. 11-28);
- :mod:`.dynamics`: the phase matrices, the event functions and the switch rules (eqs. 1-7);
- :mod:`.energy`: the energies and the rates of the energy flows;
- :mod:`.voltage`: the three voltage models (eqs. 20-28);
- :mod:`.damper`: all of it for one parameter set, as the solver and the FMI interfaces use it.

It knows nothing of brackets, series or FMI.
"""

from .barrier import DERIVED, EXPLICIT, Barrier, derive_barrier
from .damper import Damper
from .dynamics import FREE, LEFT, RIGHT
from .parameters import Bound, Parameters, parameter_info
from .voltage import CIRCUIT, COUPLED, QUASI_STATIC

__all__ = ["Barrier", "Bound", "CIRCUIT", "COUPLED", "DERIVED", "Damper", "EXPLICIT", "FREE", "LEFT", "Parameters",
           "QUASI_STATIC", "RIGHT", "derive_barrier", "parameter_info"]
