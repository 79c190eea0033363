"""The FMU driven by harmonic base motion, and the measures of its periodic response.

**The drive.** The base moves as ``y = Y sin(w t + phi)``. The FMU holds its inputs as a first
order hold over each communication step, ``y = y_k + v_k (t - t_k)``, so what it can be given is a
continuous piecewise-linear base: ``N`` steps per forcing period (``Settings.samples`` in
:mod:`piezo_fmu_harness.periodic.steady_state`), node values ``y_k = A sin(w t_k + phi)`` and slopes
``v_k = (y_{k+1} - y_k) / h`` (the velocity consistent with the displacement, so the base never
jumps and does no spurious work). The fundamental of that
interpolant is ``A sinc^2(pi/N)`` (the Fourier transform of the hat function); the nodes take
``A = Y / sinc^2(pi/N)``, so the base's fundamental is exactly ``Y sin(w t + phi)``. Its other
harmonics lie at ``(kN +- 1) w`` with amplitudes ``Y / (kN +- 1)^2`` (2.5e-4 Y at N = 64), far above
every mode of the damper's main mass.

**The state.** ``x = (p, p', q, q')`` (absolute, SI) at a Poincare section: a fixed forcing phase
``phi``. A run starts from ``x`` by resetting the FMU with ``p0, q0, dp0, dq0 = x`` and the base at
phase ``phi``; the FMU requires ``|q0 - p0| <= d/2``, so the section is moved, after a few forcing
periods, to the phase where the impact mass is farthest from both barriers. The period map
``P(x)`` is the state one forcing period later.

**Measures** (over whole orbits of a verified steady state, after one orbit that lets the circuit
of the piezoelectric patches settle, or over a long window of a motion that is not periodic): the
main mass's amplitude (half its peak-to-peak over the window; the extrema are refined on each step
by the cubic Hermite interpolant of ``p`` and ``p'``), its envelope (the smallest and largest half
peak-to-peak within one forcing period), its RMS, the
transmissibility ``amplitude / Y``, impacts per forcing cycle, the RMS of the impact voltages
``V_rms`` and the mean harvested power (``harvested_energy`` over the window).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import ctypes
import math
from typing import Optional

import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2FMUstate, fmi2Integer, fmi2Real, fmi2ValueReference

from ..fmu import Instance

#: The section state's outputs, in the order of ``x``.
STATE_OUTPUTS = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity")
#: The initial-state parameters a run starts from, in the order of ``x``.
STATE_PARAMETERS = ("p0", "dp0", "q0", "dq0")


def sinc(x: float) -> float:
    return 1.0 if x == 0.0 else math.sin(x) / x


class HarmonicDrive:
    """One FMU instance driven by the base ``y = Y sin(w t + phi)`` (see the module's text).

    Parameters
    ----------
    instance : Instance
        The FMU instance; it is reset at every :meth:`start`.
    values : dict
        FMU parameters (SI) other than the initial state.
    omega : float
        Forcing frequency ``w``, rad/s.
    amplitude : float
        Base displacement amplitude ``Y``, m.
    samples : int
        Communication steps per forcing period.
    """

    def __init__(self, instance: Instance, values: dict, omega: float, amplitude: float, samples: int):
        model = instance.model
        self.instance, self.fmu = instance, instance.fmu
        self.values = {k: v for k, v in values.items() if k not in STATE_PARAMETERS}
        self.omega, self.amplitude, self.samples = omega, amplitude, samples
        self.period = 2.0 * math.pi / omega
        self.h = self.period / samples
        self.gap = float(self.values.get("d", model.parameters["d"].start))
        self.scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
        refs = [model.inputs["base_displacement"], model.inputs["base_velocity"]]
        self._input_refs = (fmi2ValueReference * 2)(*refs)
        self._input_values = (fmi2Real * 2)()
        self._state_refs = (fmi2ValueReference * 4)(*(model.outputs[name][1] for name in STATE_OUTPUTS))
        self._state_values = (fmi2Real * 4)()
        self._real_refs = (fmi2ValueReference * 2)(model.outputs["voltage_rms"][1],
                                                    model.outputs["harvested_energy"][1])
        self._real_values = (fmi2Real * 2)()
        self._count_ref = (fmi2ValueReference * 1)(model.outputs["impact_count"][1])
        self._count_value = (fmi2Integer * 1)()
        self.phase = 0.0
        self.step_index = 0
        self.cycles = 0  # forcing cycles simulated since this drive was made
        self._nodes: list[tuple[float, float]] = []

    # -- running ----------------------------------------------------------------------------------

    def start(self, x, phase: float) -> None:
        """Reset the FMU to the state ``x`` at forcing phase ``phase`` (t = 0).

        Raises :class:`FmuRunError` if the FMU rejects it (e.g. the impact mass outside the gap).
        """
        n = self.samples
        scaled = self.amplitude / sinc(math.pi / n) ** 2
        y = [scaled * math.sin(phase + 2.0 * math.pi * k / n) for k in range(n + 1)]
        self._nodes = [(y[k], (y[k + 1] - y[k]) / self.h) for k in range(n)]
        self.phase, self.step_index = phase, 0
        initial = dict(zip(STATE_PARAMETERS, (float(v) for v in x)))
        try:
            self.instance.start({**self.values, **initial},
                                inputs={"base_displacement": self._nodes[0][0], "base_velocity": self._nodes[0][1]})
        except FMICallException as error:
            raise self.instance.failure(error) from None

    def advance(self, periods: int, record: Optional[list] = None, counts: Optional[list] = None) -> list[np.ndarray]:
        """Simulate ``periods`` forcing periods; return the section state at the end of each.

        With ``record`` (a list), append the state ``x`` after every step to it; with ``counts``,
        the ``impact_count`` after every step.
        """
        fmu, call = self.fmu, self.fmu.fmi2DoStep
        component = fmu.component
        set_real, get_real = fmu.fmi2SetReal, fmu.fmi2GetReal
        refs, values = self._input_refs, self._input_values
        state_refs, state = self._state_refs, self._state_values
        h = self.h
        sections = []
        try:
            for _ in range(periods):
                for y, v in self._nodes:
                    values[0], values[1] = y, v
                    set_real(component, refs, 2, values)
                    i = self.step_index
                    t = i * h
                    call(component, t, (i + 1) * h - t, 1)
                    self.step_index = i + 1
                    if record is not None:
                        get_real(component, state_refs, 4, state)
                        record.append(state[:])
                    if counts is not None:
                        fmu.fmi2GetInteger(component, self._count_ref, 1, self._count_value)
                        counts.append(int(self._count_value[0]))
                get_real(component, state_refs, 4, state)
                sections.append(np.array(state[:]))
                self.cycles += 1
        except FMICallException as error:
            raise self.instance.failure(error) from None
        return sections

    def state(self) -> np.ndarray:
        """The state ``x`` now."""
        self.fmu.fmi2GetReal(self.fmu.component, self._state_refs, 4, self._state_values)
        return np.array(self._state_values[:])

    def totals(self) -> tuple[int, float, float]:
        """``(impact_count, voltage_rms, harvested_energy)`` now: cumulative since the start."""
        fmu = self.fmu
        fmu.fmi2GetInteger(fmu.component, self._count_ref, 1, self._count_value)
        fmu.fmi2GetReal(fmu.component, self._real_refs, 2, self._real_values)
        return int(self._count_value[0]), float(self._real_values[0]), float(self._real_values[1])

    def clearance(self, x) -> float:
        """How far the impact mass is from the nearer barrier, ``d/2 - |q - p|`` (m); < 0 in contact."""
        return 0.5 * self.gap - abs(x[2] - x[0])

    def distance(self, a, b) -> float:
        """``max(|dp|, |dp'|/w, |dq|, |dq'|/w)`` between two states (m)."""
        return float(np.max(np.abs((np.asarray(a) - np.asarray(b)) * self.scale)))

    # -- the FMU state, to resume a marching run after Newton has reset the instance ---------------

    def save(self):
        state = fmi2FMUstate()
        try:
            self.fmu.fmi2GetFMUstate(self.fmu.component, ctypes.byref(state))
        except FMICallException as error:
            raise self.instance.failure(error) from None
        return state, self.step_index, self.phase, list(self._nodes)

    def restore(self, saved) -> None:
        state, self.step_index, self.phase, self._nodes = saved
        try:
            self.fmu.fmi2SetFMUstate(self.fmu.component, state)
        except FMICallException as error:
            raise self.instance.failure(error) from None

    def release(self, saved) -> None:
        state = saved[0]
        try:
            self.fmu.fmi2FreeFMUstate(self.fmu.component, ctypes.byref(state))
        except FMICallException:
            pass


# -- measures --------------------------------------------------------------------------------------

def hermite_extrema(p: np.ndarray, v: np.ndarray, h: float) -> tuple[float, float]:
    """The largest and smallest value of the cubic Hermite interpolant of samples ``p`` (m) with
    slopes ``v`` (m/s), ``h`` (s) apart: the extrema of the motion, not just of its samples."""
    p0, p1, m0, m1 = p[:-1], p[1:], h * v[:-1], h * v[1:]
    # dp/ds on [0, 1] is a s^2 + b s + c.
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = 6.0 * (p1 - p0) - 4.0 * m0 - 2.0 * m1
    c = m0
    candidates = [p]
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
        quadratic = np.abs(a) > 1e-300
        roots = (np.where(quadratic, (-b + disc) / (2.0 * a), -c / b),
                 np.where(quadratic, (-b - disc) / (2.0 * a), -c / b))
    for s in roots:
        inside = np.isfinite(s) & (s > 0.0) & (s < 1.0)
        s = np.where(inside, s, 0.0)
        value = ((2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0
                 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1)
        candidates.append(value[inside])
    values = np.concatenate(candidates)
    return float(values.max()), float(values.min())


def period_swings(data: np.ndarray, drive: HarmonicDrive) -> list[float]:
    """Half the peak-to-peak of ``p`` (m) within each forcing period of ``data``, the states after
    each step (the first row the start), ``drive.samples`` steps a period."""
    n = drive.samples
    return [0.5 * float(np.subtract(*hermite_extrema(data[k * n:(k + 1) * n + 1, 0], data[k * n:(k + 1) * n + 1, 1],
                                                      drive.h))) for k in range((len(data) - 1) // n)]


def measure(drive: HarmonicDrive, orbits_periods: int) -> dict:
    """Run ``orbits_periods`` more periods on ``drive`` and return the steady-state measures
    over them (see the module's text)."""
    def completed(state, count):
        # impact_count counts onsets; voltage_rms is over completed impacts (one fewer in contact).
        return count - 1 if drive.clearance(state) < 0 else count

    samples: list = [list(drive.state())]
    count0, vrms0, energy0 = drive.totals()
    drive.advance(orbits_periods, record=samples)
    count1, vrms1, energy1 = drive.totals()
    data = np.array(samples)
    p, v = data[:, 0], data[:, 1]
    top, bottom = hermite_extrema(p, v, drive.h)
    envelope = period_swings(data, drive)
    impacts = count1 - count0
    done0, done1 = completed(data[0], count0), completed(data[-1], count1)
    # The square of voltage_rms times the completed impacts is the sum of their squares.
    squares = vrms1**2 * done1 - vrms0**2 * done0
    amplitude = 0.5 * (top - bottom)
    duration = orbits_periods * drive.period
    return {
        "amplitude": amplitude,
        "amplitude_min": float(min(envelope)),
        "amplitude_max": float(max(envelope)),
        "rms": float(np.sqrt(np.mean(p[:-1] ** 2))),
        "mean_displacement": float(np.mean(p[:-1])),
        "transmissibility": amplitude / drive.amplitude,
        "impacts_per_cycle": impacts / orbits_periods,
        "V_rms": float(math.sqrt(max(squares, 0.0) / (done1 - done0))) if done1 > done0 else 0.0,
        "harvested_power": (energy1 - energy0) / duration,
        "measured_cycles": orbits_periods,
    }
