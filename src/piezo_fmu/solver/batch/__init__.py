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
  motion that is not periodic.

It is not part of the FMUs' interface; the FMU stays the reference that the studies check it
against.
"""

from __future__ import annotations

import dataclasses

from ...model.parameters import Parameters
from .attractors import SettleSettings, Settled, describe, settle, tracks
from .drive import HarmonicHold
from .ensemble import Ensemble
from .kernel import DEVICES, device_error


def damper(values: dict) -> Parameters:
    """The damper of the FMU parameter values ``values`` (SI, by the FMU's names, which are the
    :class:`~piezo_fmu.model.parameters.Parameters` fields; the initial state is not used: the
    ensemble's starts are)."""
    names = {f.name for f in dataclasses.fields(Parameters)}
    return Parameters(**{k: v for k, v in values.items() if k in names and k not in ("p0", "q0", "dp0", "dq0")},
                      p0=0.0, q0=0.0, dp0=0.0, dq0=0.0)


def damper_error(values: dict) -> str | None:
    """Why the batch engine cannot take the damper of the FMU parameter values ``values`` (None when
    it can): the modes of its contact must be distinct and none growing."""
    from .model import BatchModel
    try:
        BatchModel.of(damper(values))
    except ValueError as error:
        return str(error)
    return None


__all__ = ["DEVICES", "Ensemble", "HarmonicHold", "SettleSettings", "Settled", "damper", "damper_error", "describe",
           "device_error", "settle", "tracks"]
