"""The studies of the harness, one module or package each. Each registers its own subcommand and
options (``register(commands)``, with ``run`` set to the function that runs it), runs, reports and
draws its figures. The studies never import each other: what two of them share is infrastructure,
at the top of the package (:mod:`piezo_fmu_harness.periodic`, :mod:`~piezo_fmu_harness.drawing`,
:mod:`~piezo_fmu_harness.datasets`, ...).

**Adding a study:** a module or package here with a ``register(commands)`` function, and one line
in :data:`REGISTRY`.
"""

from __future__ import annotations

from . import basins, bifurcation, continuation, forced, fractions, load, nominal, optimize, random, sweep, two_designs

#: The subcommands, in the order ``piezo-fmu --help`` lists them.
REGISTRY = (
    nominal.register,
    sweep.register,
    two_designs.register,
    load.register,
    forced.register,
    continuation.register,
    bifurcation.register,
    basins.register,
    fractions.register,
    random.register,
    optimize.register,
    sweep.register_presets,
)
