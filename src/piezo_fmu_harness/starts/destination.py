"""Where a start goes, through the FMU: the check of a study of many starts.

The studies that march thousands of starts do it on the batch engine; the FMU is the reference
they are checked against. For a start, the FMU is marched from it (:class:`HarmonicDrive`, base
phase 0) as far as the study marched it, and then a block at a time, until its own trajectory
shows which of the drive's attractors it reaches, by the same rule, applied here to the FMU's
sections:

- an **orbit**: over the last :data:`WINDOW` periods every period makes the orbit's contact onsets
  (the period that ends at the orbit's section point ``i`` makes those of its period ``i - 1``), the
  impact mass is in contact at the section exactly when the orbit's is, and the distance to the
  orbit shrinks and ends within :data:`REACH` of its size;
- the motion **without impacts**: no contact onset in the window, and the impact mass at rest
  (``q' = 0``: after an impact it never is again);
- otherwise, at the cap, **on no orbit**: the drive's record of that kind (chaotic, quasi-periodic
  or undecided; the study's own for this start when it gave one). One trajectory of the
  FMU cannot show that a motion persists (that takes the survival of many starts): it agrees with
  the study that the start is on no orbit within the march. It is classified through the FMU too
  (:func:`piezo_fmu_harness.periodic.motion.classify`), and the class is reported beside the
  study's.

**Chaotic transients.** Where a start wanders chaotically before it settles, rounding grows by a
factor of about ``e`` a period: beyond a few dozen periods the FMU's trajectory and the batch
engine's are different trajectories, and where each settles is a matter of the last bits, in either
code. So the study passes the batch engine's sections of the start (``track``), and the FMU's
trajectory is compared with them period by period: ``diverged_at`` is the first period where they
part by more than :data:`PART` of the state's size. A check whose answers differ after the
trajectories parted, before the study's answer was known, says that this start's fate is not
predictable in double precision, not that either code is wrong; one whose answers differ while the
trajectories were together is a disagreement.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""

from __future__ import annotations

import math

import numpy as np

from ..periodic.drive import HarmonicDrive
from ..periodic.motion import classify
from .attractors import NOT_PERIODIC

#: Periods of the FMU's trajectory the rule looks at.
WINDOW = 40
#: The distance to an orbit at the end of the window, relative to the orbit's size.
REACH = 0.05
#: Periods the FMU marches beyond the study, at most, before the motion counts as not periodic.
EXTRA = 100
#: Two trajectories have parted when their sections differ by this fraction of the state's size.
PART = 1e-3


def _orbit_rule(sections: np.ndarray, onsets: np.ndarray, sides: np.ndarray, orbit: dict, scale: np.ndarray) -> bool:
    points = np.array(orbit["sections"], dtype=float)
    gaps = np.abs((sections[:, None, :] - points[None]) * scale).max(axis=2)
    nearest, distance = gaps.argmin(axis=1), gaps.min(axis=1)
    order = orbit["order"]
    pattern, orbit_sides = np.array(orbit["impacts"]), np.array(orbit["sides"])
    if not ((onsets == pattern[(nearest - 1) % order]).all() and (sides == orbit_sides[nearest]).all()):
        return False
    size = float(np.abs(points * scale).max())
    return bool(distance[-1] < distance[0] and distance[-1] <= REACH * size) or bool(distance.max() == 0.0)


def fmu_label(instance, values: dict, omega: float, amplitude: float, samples: int, start, periods: int,
              attractors: list[dict], track=None, cap: int = 0, classify_cycles: int = 40, prefer=None) -> dict:
    """March the FMU from ``start`` (``p, p', q, q'``) and say which of ``attractors`` (records of
    this drive, each with its ``id``) its trajectory reaches (see the module's text). Returns
    ``{"attractor": id or None, "motion", "periods", "diverged_at"}`` (``motion`` the class when not
    periodic; ``diverged_at`` the first period where the FMU's sections part from ``track``, the
    study's, or None). The FMU marches :data:`EXTRA` periods past the study's ``periods``, and at
    least the study's own cap on periods ``cap``, before its motion counts as on no orbit (the
    record ``prefer`` when it is one of that kind)."""
    drive = HarmonicDrive(instance, values, omega, amplitude, samples)
    drive.start(np.asarray(start, float), 0.0)
    scale = drive.scale
    sections, onsets, sides = [], [], []
    count = drive.totals()[0]
    track = None if track is None else np.asarray(track, float)
    diverged = None
    limit = max(max(periods, WINDOW) + EXTRA, cap)
    marched = 0
    while marched < limit:
        target = max(periods, WINDOW) if marched < max(periods, WINDOW) else marched + WINDOW // 2
        while marched < target:
            state = drive.advance(1)[-1]
            now = drive.totals()[0]
            sections.append(state)
            if diverged is None and track is not None and marched < len(track):
                size = max(amplitude, float(np.abs(track[marched] * scale).max()))
                if np.abs((state - track[marched]) * scale).max() > PART * size:
                    diverged = marched + 1
            onsets.append(now - count)
            sides.append(0 if drive.clearance(state) >= 0 else int(math.copysign(1, state[2] - state[0])))
            count, marched = now, marched + 1
        window = slice(len(sections) - WINDOW, None)
        s, o, d = np.array(sections[window]), np.array(onsets[window]), np.array(sides[window])
        for attractor in attractors:
            if attractor["kind"] == "orbit" and _orbit_rule(s, o, d, attractor, scale):
                return {"attractor": attractor["id"], "motion": "periodic", "periods": marched,
                        "diverged_at": diverged}
            if attractor["kind"] == "no impacts" and o.sum() == 0 and s[-1, 3] == 0.0:
                return {"attractor": attractor["id"], "motion": "periodic", "periods": marched,
                        "diverged_at": diverged}
    motion = classify(drive, classify_cycles)["motion"]
    loose = [a["id"] for a in attractors if a["kind"] in NOT_PERIODIC]
    match = prefer if prefer in loose else next(iter(loose), None)
    return {"attractor": match, "motion": motion, "periods": marched, "diverged_at": diverged}
