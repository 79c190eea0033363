"""The batch engine: the period map of many trajectories of one damper at once, for the studies of
where starts go (basins, fractions, bifurcation diagrams).

The scalar core (:mod:`piezo_fmu.solver`) integrates one damper exactly, event by event, and the
FMUs run it. This package marches arrays of trajectories under harmonic base motion, with the same
physics written a second time, in closed form between events, compiled; each code checks the other.

- :mod:`.model`: what the engine needs of one damper (the phases in closed form, their bounds);
- :mod:`.drive`: the base as the FMUs receive it (a first-order hold of ``N`` nodes a period);
- :mod:`.ensemble`: :class:`Ensemble`, many trajectories marched a block of periods at a time;
- :mod:`.kernel`: the compiled kernel that marches them, on the CPU or a GPU;
- :mod:`.attractors`: where each start goes (:func:`settle`), the orbits, and the measures of a
  motion that is not periodic;
- :mod:`.limits`: the dampers and drives the studies take (:func:`study_error` says why not).

It is not part of the FMUs' interface; the FMU stays the reference that the studies check it
against.
"""

from __future__ import annotations

from .attractors import SettleSettings, Settled, describe, settle, tracks
from .drive import HarmonicHold
from .ensemble import Ensemble
from .kernel import DEVICES, device_error
from .limits import damper, study_error


def damper_error(values: dict) -> str | None:
    """Why the batch engine cannot take the damper of the FMU parameter values ``values`` (None when
    it can): its contact must be exact in modal form (:func:`.limits.study_error` without drives)."""
    return study_error(values)


__all__ = ["DEVICES", "Ensemble", "HarmonicHold", "SettleSettings", "Settled", "damper", "damper_error", "describe",
           "device_error", "settle", "study_error", "tracks"]
