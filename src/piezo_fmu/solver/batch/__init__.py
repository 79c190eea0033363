"""The batch engine: the period map of many trajectories at once (issue 27).

The scalar core (:mod:`piezo_fmu.solver`) integrates one damper exactly, event by event; the FMUs
run it. Studies that ask where thousands of starts go (basins, fractions, bifurcation diagrams)
need the same motion for many trajectories at once. This package marches arrays of them under
harmonic base motion, with the same physics, in closed form between events:

- :mod:`.drive`: the base as the FMUs receive it (a first-order hold of N nodes a period);
- :mod:`.phases`: free flight and contact in closed form, and the bounds that make event
  location rigorous;
- :mod:`.events`: the next switch of each trajectory, located without a step that could jump it;
- :mod:`.rounds`: a hold step's events, round by round, with the switch rules;
- :mod:`.ensemble`: :class:`Ensemble`, many trajectories marched period by period;
- :mod:`.namespace`: numpy on the CPU, or CuPy on a GPU (the array API standard).

It is not part of the FMUs; the FMU stays the reference that the studies check it against.
"""

from .drive import HarmonicHold
from .ensemble import Ensemble
from .namespace import DEVICES, namespace, to_numpy

__all__ = ["DEVICES", "Ensemble", "HarmonicHold", "namespace", "to_numpy"]
