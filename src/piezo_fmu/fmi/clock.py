"""The co-simulation FMU's clock: where a communication step ends, and which starts continue it.

Hosts compute their communication points in different arithmetic: ``t0 + i * h``, ``t += h``,
integer nanoseconds divided by ``1e9`` (OSP libcosim, the project's C host), or ``start + n * h``
with the step as the difference to the next point (fmpy's ``simulate_fmu``, Reference-FMUs'
fmusim). Their points for the same grid differ in the last bits. The FMU therefore

- ends a step at ``current_time + step_size``, moved to the nearest whole nanosecond when it lies
  within :data:`SNAP` ``* max(1 s, |end|)`` of it: hosts that round the same grid differently
  hand the core the same step ends, and so get the same bits;
- takes a step's ``current_time`` as its own time ``t`` when it lies within :data:`ACCEPT`
  ``* max(1 s, |t|)`` of it: the snap plus any host's rounding of its grid (a few ulp), with a
  margin of ``1e-12 * max(1 s, |t|)`` (about 4500 ulp) to spare. A start farther away skips or
  repeats time and is refused.

Each step's end is computed from the host's ``current_time``, never from the FMU's own time, so
the two cannot drift apart however long the run.

Pure functions of floats, without numpy: :meth:`piezo_fmu.fmi.cosim.CoSimulation.step` calls them
at every step, and the tests compile these very functions with numba to run them over 10^8
steps of each host's arithmetic.
"""

from __future__ import annotations

#: A step's end within ``SNAP * max(1 s, |end|)`` of a whole nanosecond is moved onto it.
SNAP = 1e-12
#: A step's start within ``ACCEPT * max(1 s, |t|)`` of the FMU's time ``t`` continues it.
ACCEPT = 2 * SNAP


def continues(t_now: float, current_time: float) -> bool:
    """Whether a step from ``current_time`` (s) continues the FMU's time ``t_now`` (s): within
    ``ACCEPT * max(1 s, |t_now|)`` of it (False for NaN)."""
    return abs(current_time - t_now) <= ACCEPT * max(1.0, abs(t_now))


def step_end(t_now: float, current_time: float, step_size: float) -> float:
    """The FMU's time after a step from ``current_time`` by ``step_size`` (s), the FMU being at
    ``t_now`` (a start that :func:`continues` it): ``current_time + step_size``, moved to the
    nearest whole nanosecond when it lies within ``SNAP * max(1 s, |end|)`` of it and that
    nanosecond is after ``t_now``. Never before ``t_now``: a step shorter than the clock's
    tolerance that ends at or before the FMU's time (it started before it, within
    :data:`ACCEPT`) leaves the FMU where it is."""
    end = current_time + step_size
    snapped = round(end * 1e9) / 1e9
    if abs(snapped - end) <= SNAP * max(1.0, abs(end)) and snapped > t_now:
        return snapped
    return end if end > t_now else t_now
