"""What a run records: the state at an instant and each contact with a barrier."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple


class State(NamedTuple):
    """The state at time ``t`` (s): absolute displacements (m) and velocities (m/s).

    ``side`` is 0 in free flight, +1 in contact with the right barrier (``q - p = +d/2`` side),
    -1 with the left one. ``y`` (m) and ``v`` (m/s) are the base displacement and velocity.
    """

    t: float
    p: float
    dp: float
    q: float
    dq: float
    side: int
    y: float
    v: float


@dataclass
class Impact:
    """One contact with a barrier.

    ``time`` (s) is the onset, ``side`` +1 (right) or -1 (left), ``rel_velocity`` (m/s) the
    relative velocity ``q' - p'`` at onset before the tip mass is captured,
    ``max_deflection`` (m) the peak barrier tip deflection, ``voltage`` (V) the impact voltage
    ``V_i``: ``k_V max_deflection`` under ``voltage_model = 0``, the peak ``|V|`` across the load
    during the contact (ends included) under 1 and 2 (NaN while the contact lasts);
    ``duration`` (s) the contact time (NaN while the contact lasts).
    ``dp_*``/``dq_*`` (m/s) are the absolute velocities just before and after the onset and the
    separation switches, and ``capture_loss``/``release_loss`` (J) the plastic losses there.
    """

    time: float
    side: int
    rel_velocity: float
    dp_before: float
    dq_before: float
    dp_after: float
    dq_after: float
    capture_loss: float
    max_deflection: float = 0.0
    voltage: float = math.nan
    duration: float = math.nan
    dp_sep_before: float = math.nan
    dq_sep_before: float = math.nan
    dp_sep_after: float = math.nan
    dq_sep_after: float = math.nan
    release_loss: float = math.nan
