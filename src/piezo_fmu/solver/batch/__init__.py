"""The batch engine: the period map of many trajectories at once (issue 27).

The scalar core (:mod:`piezo_fmu.solver`) integrates one damper exactly, event by event; the FMUs
run it. Studies that ask where thousands of starts go (basins, fractions, bifurcation diagrams)
need the same motion for many trajectories at once. This package marches arrays of them under
harmonic base motion, with the same physics, in closed form between events:

- :mod:`.drive`: the base as the FMUs receive it (a first-order hold of N nodes a period);
- :mod:`.phases`: free flight and contact in closed form, and the bounds that make event
  location rigorous;
- :mod:`.kernel_source`: one trajectory through its hold steps as scalar code: free flight and
  contact in closed form, the rigorous location of every switch, the switch rules;
- :mod:`.kernel`: that source compiled with numba for the CPU and for a GPU (numba's CUDA target);
  :mod:`.kernel_cache`, where its compiled code is kept;
- :mod:`.ensemble`: :class:`Ensemble`, many trajectories marched a block of periods at a time on
  the kernel;
- :mod:`.array_ensemble`, :mod:`.events`, :mod:`.rounds`, :mod:`.namespace`: the array engine, the
  same physics written with operations on arrays of the array API standard (numpy,
  ``array-api-strict``, CuPy): the kernel's test oracle;
- :mod:`.orbits`: Newton, verification and multipliers on the engine, the motion without impacts;
- :mod:`.settle`: where each of many starts goes, by marching (the rule of issue 26);
- :mod:`.trajectories`: a motion's Lyapunov exponent and modulation, and a start's track.

It is not part of the FMUs; the FMU stays the reference that the studies check it against.
"""

import dataclasses

from ...model.parameters import Parameters
from .drive import HarmonicHold
from .ensemble import Ensemble
from .ensemble import DEVICES
from .namespace import namespace, to_numpy
from .settle import SettleSettings, Settled, describe, settle
from .trajectories import tracks


def device_error(device: str) -> str | None:
    """Why the kernel cannot run on ``device`` here (None when it can)."""
    if device not in DEVICES:
        return f"device = {device!r} is not known; allowed values {DEVICES}"
    if device == "gpu":
        from .kernel import gpu_error
        return gpu_error()
    return None


def damper(values: dict) -> Parameters:
    """The damper of the FMU parameter values ``values`` (SI, by the FMU's names, which are the
    :class:`~piezo_fmu.model.parameters.Parameters` fields; the initial state is not used: the
    ensemble's starts are)."""
    names = {f.name for f in dataclasses.fields(Parameters)}
    return Parameters(**{k: v for k, v in values.items() if k in names and k not in ("p0", "q0", "dp0", "dq0")},
                      p0=0.0, q0=0.0, dp0=0.0, dq0=0.0)


def damper_error(values: dict) -> str | None:
    """Why the batch engine cannot take the damper of the FMU parameter values ``values`` (None when
    it can): the modes of its contact must be distinct and decaying."""
    from .phases import BatchModel
    try:
        BatchModel.of(damper(values))
    except ValueError as error:
        return str(error)
    return None


__all__ = ["DEVICES", "Ensemble", "device_error", "damper_error", "HarmonicHold", "SettleSettings", "Settled", "damper", "describe", "namespace",
           "settle", "to_numpy", "tracks"]
