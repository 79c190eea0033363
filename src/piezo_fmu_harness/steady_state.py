"""The periodic response of the FMU to harmonic base motion: the drive, shooting, verification
and the steady-state measures of one frequency.

**The drive.** The base moves as ``y = Y sin(w t + phi)``. The FMU holds its inputs as a first
order hold over each communication step, ``y = y_k + v_k (t - t_k)``, so what it can be given is a
continuous piecewise-linear base: ``N`` steps per forcing period (:attr:`Settings.samples`), node
values ``y_k = A sin(w t_k + phi)`` and slopes ``v_k = (y_{k+1} - y_k) / h`` (the velocity consistent
with the displacement, so the base never jumps and does no spurious work). The fundamental of that
interpolant is ``A sinc^2(pi/N)`` (the Fourier transform of the hat function); the nodes take
``A = Y / sinc^2(pi/N)``, so the base's fundamental is exactly ``Y sin(w t + phi)``. Its other
harmonics lie at ``(kN +- 1) w`` with amplitudes ``Y / (kN +- 1)^2`` (2.5e-4 Y at N = 64), far above
every mode of the damper's main mass.

**The state.** ``x = (p, p', q, q')`` (absolute, SI) at a Poincare section: a fixed forcing phase
``phi``. A run starts from ``x`` by resetting the FMU with ``p0, q0, dp0, dq0 = x`` and the base at
phase ``phi``; the FMU requires ``|q0 - p0| <= d/2``, so the section is moved, after a few forcing
periods, to the phase where the impact mass is farthest from both barriers. The period map
``P(x)`` is the state one forcing period later.

**Steady state.** Time-marching at ``zeta = 0.0016`` takes minutes of simulated time, so the
periodic orbit is found by shooting: Newton on ``P^n(x) - x`` (``n`` the order of the orbit:
1, or a multiple period detected from the marched sections) with finite-difference Jacobians,
solved by least squares (the impact mass's free drift is a neutral direction when it makes no
impact) and with a backtracking line search. A vibro-impact map is only piecewise smooth, so
Newton alternates with blocks of time-marching. An orbit is accepted only after a verification
run: from ``x`` the section returns within the tolerance after ``n``, ``2n`` and ``3n`` periods.
Marching alone may also settle (the sections' geometric tail within the tolerance), and is
verified the same way. When the cap on simulated cycles is reached first, the point is reported
as not settled, with measures from its last periods. Distances between states are the largest
of ``|dp|, |dp'|/w, |dq|, |dq'|/w`` (m); the tolerance is relative to ``Y``.

**Measures** (over whole orbits of a verified steady state, after one orbit that lets the circuit
of the piezoelectric patches settle): the main mass's amplitude (half its peak-to-peak; the extrema
are refined on each step by the cubic Hermite interpolant of ``p`` and ``p'``), its RMS, the
transmissibility ``amplitude / Y``, impacts per forcing cycle, the RMS of the impact voltages
``V_rms`` and the mean harvested power (``harvested_energy`` over the window).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2FMUstate, fmi2Integer, fmi2Real, fmi2ValueReference

from .fmu import FmuRunError, Instance

#: The section state's outputs, in the order of ``x``.
STATE_OUTPUTS = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity")
#: The initial-state parameters a run starts from, in the order of ``x``.
STATE_PARAMETERS = ("p0", "dp0", "q0", "dq0")


@dataclass(frozen=True)
class Settings:
    """How one frequency's steady state is found and checked.

    Attributes
    ----------
    samples : int
        Communication steps per forcing period (the base's nodes), >= 16.
    tolerance : float
        Steady-state tolerance on the section's return, relative to the base amplitude ``Y``.
    max_cycles : int
        Cap on the forcing cycles simulated for one frequency (Newton's evaluations included).
    newton_iterations : int
        Newton iterations per attempt; 0 finds the steady state by time-marching alone.
    max_order : int
        Longest period of an orbit looked for, in forcing periods.
    warmup_cycles : int
        Forcing cycles marched from the guess before the first Newton attempt (the last one
        chooses the section's phase).
    march_cycles : int
        Forcing cycles marched between Newton attempts.
    """

    samples: int = 64
    tolerance: float = 1e-6
    max_cycles: int = 400
    newton_iterations: int = 12
    max_order: int = 4
    warmup_cycles: int = 2
    march_cycles: int = 8

    #: Newton attempts per frequency (each after a block of marching).
    NEWTON_ATTEMPTS = 3
    #: Finite-difference step of the Jacobian, relative to the state's scale.
    FD_STEP = 1e-7
    #: Returns the verification run checks, in orbits.
    VERIFY_ORBITS = 3


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

    def advance(self, periods: int, record: Optional[list] = None) -> list[np.ndarray]:
        """Simulate ``periods`` forcing periods; return the section state at the end of each.

        With ``record`` (a list), append the state ``x`` after every step to it.
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
    impacts = count1 - count0
    done0, done1 = completed(data[0], count0), completed(data[-1], count1)
    # The square of voltage_rms times the completed impacts is the sum of their squares.
    squares = vrms1**2 * done1 - vrms0**2 * done0
    amplitude = 0.5 * (top - bottom)
    duration = orbits_periods * drive.period
    return {
        "amplitude": amplitude,
        "rms": float(np.sqrt(np.mean(p[:-1] ** 2))),
        "mean_displacement": float(np.mean(p[:-1])),
        "transmissibility": amplitude / drive.amplitude,
        "impacts_per_cycle": impacts / orbits_periods,
        "V_rms": float(math.sqrt(max(squares, 0.0) / (done1 - done0))) if done1 > done0 else 0.0,
        "harvested_power": (energy1 - energy0) / duration,
        "measured_cycles": orbits_periods,
    }


# -- the steady state of one frequency -------------------------------------------------------------

class SteadyState:
    """Finds, verifies and measures the steady state at one frequency (see the module's text)."""

    def __init__(self, drive: HarmonicDrive, settings: Settings):
        self.drive, self.settings = drive, settings
        self.tolerance = settings.tolerance * drive.amplitude
        self.newton_iterations_used = 0

    def _budget_left(self, periods: int) -> bool:
        return self.drive.cycles + periods <= self.settings.max_cycles

    def period_map(self, x, phase: float, order: int) -> Optional[np.ndarray]:
        """``P^order(x)``, or ``None`` if the FMU rejects the start ``x`` (outside the gap) or
        the cap on cycles would be passed."""
        if not self._budget_left(order):
            return None
        try:
            self.drive.start(x, phase)
            return self.drive.advance(order)[-1]
        except FmuRunError:  # the FMU checks the initial state at its first step
            return None

    def newton(self, x, phase: float, order: int) -> tuple[np.ndarray, bool]:
        """Newton on ``P^order(x) - x``; returns the last iterate and whether its residual is
        within a tenth of the tolerance."""
        drive, s = self.drive, self.drive.scale
        fx = self.period_map(x, phase, order)
        if fx is None:
            return x, False
        residual = (fx - x) * s
        for _ in range(self.settings.newton_iterations):
            norm = float(np.max(np.abs(residual)))
            if norm <= 0.1 * self.tolerance:
                return x, True
            self.newton_iterations_used += 1
            step = self.settings.FD_STEP * max(drive.amplitude, float(np.max(np.abs(x * s))))
            jacobian = np.empty((4, 4))
            for i in range(4):
                for sign in (1.0, -1.0):  # the other side when the FMU rejects a shifted start
                    shifted = x.copy()
                    shifted[i] += sign * step / s[i]
                    fi = self.period_map(shifted, phase, order)
                    if fi is not None:
                        jacobian[:, i] = sign * ((fi - fx) * s) / step
                        break
                else:
                    return x, False
            delta = np.linalg.lstsq(jacobian - np.eye(4), -residual, rcond=1e-12)[0] / s
            for _ in range(5):  # backtracking: halve the step until the residual falls
                trial = x + delta
                ft = self.period_map(trial, phase, order)
                if ft is not None and float(np.max(np.abs((ft - trial) * s))) < norm:
                    x, fx, residual = trial, ft, (ft - trial) * s
                    break
                delta = 0.5 * delta
            else:
                return x, False
        return x, float(np.max(np.abs(residual))) <= 0.1 * self.tolerance

    def returns(self, x, sections: list, order: int) -> tuple[Optional[int], float]:
        """The least period (<= ``order``) at which ``sections`` (after ``x``) return to ``x``
        within the tolerance at every multiple, and the largest such return distance (m);
        ``(None, smallest distance)`` if none does."""
        distances = [self.drive.distance(section, x) for section in sections]
        total = len(distances)
        for period in range(1, order + 1):
            worst = max(distances[k - 1] for k in range(period, total + 1, period))
            if worst <= self.tolerance:
                return period, worst
        return None, min(distances)

    def solve(self, x, phase: float) -> dict:
        """The steady state from the guess ``x`` at section phase ``phase``: a JSON-safe record
        with ``settled``, ``method``, ``order``, the measures, the cycles simulated and the final
        ``state`` and ``phase`` (the next frequency's guess)."""
        drive, settings = self.drive, self.settings
        verify = settings.VERIFY_ORBITS
        self._start_marching(np.asarray(x, float), phase)
        history = self._choose_section()
        attempts = 0
        while True:
            x, phase = history[-1], drive.phase
            if settings.newton_iterations > 0 and attempts < settings.NEWTON_ATTEMPTS and drive.clearance(x) > 0:
                attempts += 1
                saved = drive.save()
                try:
                    for order in self._orders(history):
                        candidate, converged = self.newton(x, phase, order)
                        if converged and self._budget_left(verify * order):
                            drive.start(candidate, phase)
                            period, error = self.returns(candidate, drive.advance(verify * order), order)
                            if period is not None:
                                return self._settled(candidate, phase, period, error, "newton")
                    drive.restore(saved)
                finally:
                    drive.release(saved)
            order = self._marched_order(history)
            if order is not None and self._budget_left(verify * order):
                # Verified by marching on: the next orbits must return within the tolerance.
                sections = drive.advance(verify * order)
                period, error = self.returns(x, sections, order)
                if period is not None:
                    return self._settled(x, phase, period, error, "marching")
                history += sections
                continue
            block = min(settings.march_cycles, settings.max_cycles - drive.cycles)
            if block <= 0:
                break
            history += drive.advance(block)
        return self._not_settled()

    # -- pieces of solve ---------------------------------------------------------------------------

    def _start_marching(self, x, phase: float) -> None:
        """Start the drive from ``x``; a guess with the impact mass outside the gap (a previous
        frequency's state in contact) is moved onto the nearer barrier first."""
        if self.drive.clearance(x) < 0:
            x = x.copy()
            x[2] = x[0] + math.copysign(0.5 * self.drive.gap, x[2] - x[0])
            x[3] = x[1]
        self.drive.start(x, phase)

    def _choose_section(self) -> list[np.ndarray]:
        """March the first periods, then move the section to the phase of the last period where
        the impact mass is farthest from the barriers, unless it already is at least half that
        far. Returns the sections marched at the final phase (the drive stands at the last)."""
        drive, settings = self.drive, self.settings
        history = [drive.state()]
        history += drive.advance(max(0, min(settings.warmup_cycles, settings.max_cycles) - 1))
        record: list = []
        history += drive.advance(1, record=record)
        clearances = [drive.clearance(state) for state in record]
        best = int(np.argmax(clearances))
        if clearances[-1] > 0 and clearances[-1] >= 0.5 * clearances[best]:
            return history
        phase = (drive.phase + 2.0 * math.pi * (best + 1) / drive.samples) % (2.0 * math.pi)
        state = np.array(record[best])
        drive.start(state, phase)
        return [state]

    def _orders(self, history: list) -> list[int]:
        """Orders for Newton to try: 1, then the order the marched sections suggest."""
        suggested = self._suggested_order(history)
        return [1] if suggested == 1 else [1, suggested]

    def _suggested_order(self, history: list) -> int:
        """The ``n`` <= max_order whose return ``|x_k - x_{k-n}|`` is smallest over the last sections."""
        drive, top = self.drive, self.settings.max_order
        if len(history) < top + 1:
            return 1
        gaps = [drive.distance(history[-1], history[-1 - n]) for n in range(1, top + 1)]
        best = int(np.argmin(gaps)) + 1
        return best if gaps[best - 1] < 0.1 * gaps[0] else 1

    def _marched_order(self, history: list) -> Optional[int]:
        """The order at which the marched sections have converged: their geometric tail, estimated
        from the returns over the last orbits, is within the tolerance. ``None`` if none has."""
        drive = self.drive
        for order in range(1, self.settings.max_order + 1):
            span = 4 * order
            if len(history) < span + order:
                break
            returns = [drive.distance(history[k], history[k - order])
                       for k in range(len(history) - span, len(history))]
            first, last = returns[0], returns[-1]
            if last == 0.0:
                return order
            if first <= 0.0 or last >= first:
                continue
            ratio = (last / first) ** (1.0 / (len(returns) - 1))
            if last * ratio / (1.0 - ratio) + last <= self.tolerance:
                return order
        return None

    def _settled(self, x, phase: float, period: int, error: float, method: str) -> dict:
        # The verification left the drive at a section of the orbit, more than one orbit after its
        # start: the circuit has settled; two orbits are measured.
        bookkeeping = self._bookkeeping(x, phase)
        return {"settled": True, "method": method, "order": period, "return_error": error,
                **measure(self.drive, 2 * period), **bookkeeping}

    def _not_settled(self) -> dict:
        drive = self.drive
        bookkeeping = self._bookkeeping(drive.state(), drive.phase)
        return {"settled": False, "method": "none", "order": None, "return_error": None,
                **measure(drive, 2), **bookkeeping}

    def _bookkeeping(self, x, phase: float) -> dict:
        """The cycles spent finding and verifying the steady state (the measured ones come on top)
        and where it stands: the next frequency's guess."""
        return {"cycles": self.drive.cycles, "newton_iterations": self.newton_iterations_used,
                "state": [float(v) for v in x], "phase": float(phase)}
