"""What a motion that is not periodic is: quasi-periodic, strongly modulated, chaotic, or a
transient still on its way to an orbit.

From where the drive stands, ``periods`` forcing periods are marched and their Poincare sections
kept. Two measures decide:

- **The largest Lyapunov exponent** (per forcing period), from the period map's Jacobians along
  the trajectory: a tangent vector is carried from section to section, ``v <- J v / |J v|``, and
  the exponent is the mean of ``ln |J v|``. The FMU starts only with the impact mass inside the
  gap, so the Jacobian of ``P^m`` is taken from each section where it is free to the next one
  (``m`` periods on), by forward differences through the FMU (five runs); the drive's own state is
  saved and restored around them.
- **The modulation** of the amplitude: the smallest and largest half peak-to-peak of one period
  over the window, as a fraction of the largest.

The class: ``chaotic`` when the exponent exceeds :data:`CHAOS` (a disturbance grows by more than 5%
a period on average); ``transient`` when it is below :data:`TRANSIENT` (the motion contracts by
more than 1% a period: it is still converging, to an orbit the cap on cycles did not wait for);
otherwise ``quasi-periodic`` (an invariant circle in the section, the exponent zero), or
``strongly modulated`` when the amplitude swings by more than :data:`STRONG` of its largest value.
A transient that contracts more slowly than 1% a period reads as quasi-periodic over the window.

**A class from one window is a hint, not a verdict**: a chaotic transient has a positive
exponent too, and one trajectory marched to a cap cannot show that its motion persists. The
frequency response and the continuation's seeds report such a motion as :func:`undecided`, keeping
the window's class beside it; the studies of many starts call a motion chaotic only once the
survival of their starts shows that it persists (:mod:`piezo_fmu_harness.starts.transients`).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math

import numpy as np

from .drive import HarmonicDrive, period_swings

#: Largest Lyapunov exponent (per forcing period) beyond which a motion is chaotic.
CHAOS = 0.05
#: ... and below which it is a transient, still contracting onto an orbit (1% a period).
TRANSIENT = -0.01
#: Amplitude modulation (range over largest) beyond which a quasi-periodic motion is strongly modulated.
STRONG = 0.5
#: Forward-difference step of the Jacobians, relative to the section state's size.
STEP = 1e-7


def classify(drive: HarmonicDrive, periods: int = 40) -> dict:
    """March ``periods`` more periods from where ``drive`` stands and classify the motion (see the
    module's text); the drive ends where the march ended. JSON-safe: ``motion``,
    ``lyapunov_exponent`` (1/period), ``lyapunov_periods``, ``modulation`` and ``sections`` (the
    section states, m and m/s)."""
    record: list = []
    first = drive.state()
    sections = [first] + drive.advance(periods, record=record)
    saved = drive.save()
    try:
        exponent, counted = _lyapunov(drive, sections)
    finally:
        drive.restore(saved)
        drive.release(saved)
    swings = period_swings(np.array([first] + record), drive)
    modulation = (max(swings) - min(swings)) / max(swings) if max(swings) > 0 else 0.0
    motion = kind(exponent, modulation) if counted else "unclassified"
    return {"motion": motion, "lyapunov_exponent": exponent if counted else None, "lyapunov_periods": counted,
            "modulation": float(modulation), "sections": [[float(v) for v in s] for s in sections]}


def kind(exponent: float, modulation: float) -> str:
    """The class of a motion that is not periodic, from its largest Lyapunov exponent (per period)
    and its modulation (see the module's text)."""
    if exponent > CHAOS:
        return "chaotic"
    if exponent < TRANSIENT:
        return "transient"
    return "strongly modulated" if modulation > STRONG else "quasi-periodic"


def undecided(record: dict) -> dict:
    """A :func:`classify` record of one trajectory marched to a cap, as the frequency response
    reports it: ``motion`` "undecided (converging)" when its exponent says it still contracts, else
    "undecided"; the window's class kept as ``window_class``."""
    exponent = record.get("lyapunov_exponent")
    converging = exponent is not None and exponent < TRANSIENT
    return {**record, "window_class": record["motion"],
            "motion": "undecided (converging)" if converging else "undecided"}


def _lyapunov(drive: HarmonicDrive, sections: list) -> tuple[float, int]:
    """The mean growth rate of a tangent vector along ``sections``, per period, and the periods it
    covers (from the first section where the impact mass is free to the last)."""
    free = [k for k, state in enumerate(sections) if drive.clearance(state) > 0]
    phase, scale = drive.phase, drive.scale
    vector = np.ones(4) / 2.0
    total, counted = 0.0, 0
    for a, b in zip(free, free[1:]):
        m, z = b - a, np.asarray(sections[a])
        drive.start(z, phase)
        image = drive.advance(m)[-1]
        h = STEP * max(drive.amplitude, float(np.max(np.abs(z * scale))))
        jacobian = np.empty((4, 4))
        for i in range(4):
            shifted = z.copy()
            shifted[i] += h / scale[i]
            drive.start(shifted, phase)
            jacobian[:, i] = (drive.advance(m)[-1] - image) * scale / h
        vector = jacobian @ vector
        norm = float(np.linalg.norm(vector))
        if not math.isfinite(norm) or norm == 0.0:
            break
        total += math.log(norm)
        vector /= norm
        counted += m
    return (total / counted if counted else 0.0), counted
