"""The frequency response (issue 13): the damper shaken at its base, swept up and down in
frequency, with and without the damper, through the FMU.

The base moves as ``y = Y sin(w t)``, ``Y`` given directly or as ``A / w^2`` for an acceleration
amplitude ``A``; ``w`` runs over ``count`` evenly spaced values between ``ratio_min`` and
``ratio_max`` times ``sqrt(K/M)``. At each frequency the steady state is found by shooting and
verified by simulation (:mod:`piezo_fmu_harness.steady_state`), starting from the previous frequency's final
state, so that a sweep follows one branch of coexisting orbits until it ends (a jump). Four chains
run: with and without the damper, each up and down. Without the damper, the gap is widened until
the impact mass cannot reach a barrier, as for Fig. 3a.

The chains are independent, and each is a sequence of dependent points: a point is one task on
the sweep engine (process pool, Dask or in-process), and the next point of its chain is
submitted as soon as it returns, so four chains keep two cores busy. Each finished point is
appended to ``points.jsonl``; ``--resume`` continues every chain from its last finished point.

A folder ends up with ``frequency_response.json`` (what was asked), ``points.jsonl``, and the
results that :mod:`piezo_fmu_harness.frequency_results` writes: ``frequency_response.nc`` (xarray,
units in attributes), ``frequency_response.csv``, ``summary.json`` and the figures
``amplitude.png``, ``power.png``, ``impacts.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from .drive import STATE_PARAMETERS, HarmonicDrive
from .fmu import FmuModel, FmuRunError, Instance
from .steady_state import Settings, SteadyState
from .store import PointStore, open_folder

HEADER_FILE = "frequency_response.json"
#: The four chains, in the order their first points are submitted (the costly ones first).
CHAINS = (("with", "up"), ("with", "down"), ("without", "up"), ("without", "down"))
DAMPER_CASES, DIRECTIONS = ("with", "without"), ("up", "down")
#: The band's defaults: w / sqrt(K/M) from 0.5 to 2 at 61 frequencies (at least 60, and sqrt(K/M)
#: itself one of them, a step of 0.025), at most 400 cycles each, at least 2 frequencies.
BAND_DEFAULTS = {"ratios": (0.5, 2.0), "count": 61, "max_cycles": 400, "fewest": 2}
#: Base displacement amplitude (m): the no-damper response at sqrt(K/M) would be 1/(2 zeta) = 316
#: times it, so 1 mm makes the nominal damper impact over a band around resonance.
DEFAULT_AMPLITUDE = 1e-3
DEFAULT_VOLTAGE_MODEL = 1
#: Up and down sweeps "differ" at a frequency when both settled and their orbits' orders or
#: impacts per cycle differ, or their amplitudes differ by more than this (relative).
BAND_TOLERANCE = 1e-3
#: Measures per point, with their units and descriptions (the Dataset's variables).
MEASURES = {
    "amplitude": ("m", "steady-state amplitude of the main mass, half its peak-to-peak (over the window when not "
                       "periodic)"),
    "amplitude_min": ("m", "smallest half peak-to-peak of p within one forcing period (the envelope's low edge)"),
    "amplitude_max": ("m", "largest half peak-to-peak of p within one forcing period (the envelope's high edge)"),
    "rms": ("m", "RMS of the main mass's displacement p over the steady-state orbit"),
    "transmissibility": ("1", "amplitude / base displacement amplitude Y"),
    "impacts_per_cycle": ("1", "impacts (contact onsets, both barriers) per forcing cycle"),
    "V_rms": ("V", "RMS of the impact voltages in steady state (eq. 30, under the voltage model)"),
    "harvested_power": ("W", "mean power into both loads in steady state (harvested_energy / time)"),
    "mean_displacement": ("m", "mean of p over the steady-state orbit"),
    "return_error": ("m", "largest return distance of the verified section (settled points)"),
    "cycles": ("1", "forcing cycles simulated to find, verify, measure and check the orbits (the window of a motion "
                    "that is not periodic comes on top)"),
    "stability_cycles": ("1", "of those, the cycles of the stability checks (Floquet multipliers)"),
    "escape_cycles": ("1", "of those, the cycles of the search on from unstable orbits"),
    "newton_iterations": ("1", "Newton iterations spent"),
    "order": ("1", "period of the orbit in forcing periods (0: not periodic)"),
    "max_multiplier": ("1", "largest modulus of the orbit's Floquet multipliers, the free impact mass's neutral pair "
                            "left out (< 1: stable)"),
    "stability_margin": ("1", "1 - max_multiplier"),
    "multiplier_error": ("1", "|max_multiplier at step h - at step 4h|: the accuracy of the multipliers"),
    "unstable_orbits": ("1", "unstable periodic orbits met on the way at this frequency (unstable_orbits.csv)"),
    "seconds": ("s", "wall time of the point in its worker"),
}


@dataclass(frozen=True)
class FrequencySpec:
    """A frequency-response study (SI).

    Attributes
    ----------
    ratios : tuple
        Frequency ratios ``w / sqrt(K/M)``, increasing.
    natural : float
        ``sqrt(K/M)``, rad/s.
    amplitude, acceleration : float or None
        Base displacement amplitude ``Y`` (m), or acceleration amplitude ``A`` (m/s^2); one is set.
    values : dict
        FMU parameters of the damper (``--set``, ``voltage_model``, ``R_load``).
    wide_gap : float
        Gap ``d`` (m) of the runs without the damper.
    settings : Settings
        How each steady state is found.
    """

    ratios: tuple
    natural: float
    amplitude: Optional[float]
    acceleration: Optional[float]
    values: dict
    wide_gap: float
    settings: Settings = field(default_factory=Settings)

    @property
    def omegas(self) -> np.ndarray:
        return np.array(self.ratios) * self.natural

    def base_amplitude(self, omega: float) -> float:
        """``Y`` (m) at ``omega`` (rad/s)."""
        return self.amplitude if self.amplitude is not None else self.acceleration / omega**2

    def chain_values(self, damper: str) -> dict:
        return dict(self.values) if damper == "with" else {**self.values, "d": self.wide_gap}

    def sequence(self, direction: str) -> list[int]:
        """Frequency indices in the order a chain visits them."""
        indices = list(range(len(self.ratios)))
        return indices if direction == "up" else indices[::-1]

    def index(self, chain: int, frequency: int) -> int:
        """The record index of a point: unique over the four chains."""
        return chain * len(self.ratios) + frequency

    def to_dict(self) -> dict:
        return {"ratios": list(self.ratios), "natural_rad_per_s": self.natural, "amplitude_m": self.amplitude,
                "acceleration_m_per_s2": self.acceleration, "values": dict(self.values),
                "wide_gap_m": self.wide_gap, "settings": asdict(self.settings)}


def wide_gap(spec_amplitude: float, peak_transmissibility: float) -> float:
    """A gap (m) the impact mass of the runs without the damper cannot cross: the nominal case's
    1 m, or four times the largest linear amplitude when that is larger."""
    return max(1.0, 4.0 * spec_amplitude * peak_transmissibility)


def linear_transmissibility(omega, M: float, K: float, C: float):
    """``|X/Y|`` of the base-excited oscillator (absolute displacement over base amplitude)."""
    omega = np.asarray(omega, float)
    return np.sqrt((K**2 + (C * omega) ** 2) / ((K - M * omega**2) ** 2 + (C * omega) ** 2))


# -- one point, in a worker ------------------------------------------------------------------------

def solve_point(instance: Instance, index: int, values: dict, omega: float, amplitude: float,
                settings: Settings, state, phase: float) -> dict:
    """The steady state at ``omega`` from the guess ``(state, phase)``: a JSON-safe record (a
    task of the sweep engine)."""
    begin, begin_cpu = time.perf_counter(), time.process_time()
    record = {"index": index, "omega": omega, "base_amplitude": amplitude}
    try:
        drive = HarmonicDrive(instance, values, omega, amplitude, settings.samples)
        record.update(status="ok", error=None, **SteadyState(drive, settings).solve(state, phase))
    except FmuRunError as error:
        record.update(status="error", error=str(error), settled=False)
    record["seconds"] = time.perf_counter() - begin
    record["cpu_seconds"] = time.process_time() - begin_cpu
    return record


# -- the study -------------------------------------------------------------------------------------

@dataclass
class FrequencyRun:
    """One frequency-response study and its folder; ``done`` holds the finished records."""

    spec: FrequencySpec
    folder: Path
    done: dict
    header: dict
    start_over: bool

    def begin(self) -> None:
        if self.start_over:
            PointStore(self.folder).clear()
        (self.folder / HEADER_FILE).write_text(json.dumps(self.header, indent=2) + "\n")

    @property
    def total(self) -> int:
        return len(CHAINS) * len(self.spec.ratios)

    def first_tasks(self) -> list[tuple]:
        """The first unfinished point of each chain, with its guess (the last finished state)."""
        tasks = []
        for chain in range(len(CHAINS)):
            task = self._task(chain, self._finished_in(chain))
            if task is not None:
                tasks.append(task)
        return tasks

    def follow(self, tag, record: dict) -> list[tuple]:
        """The next point of the chain ``tag`` once ``record`` is in."""
        chain, position = tag
        task = self._task(chain, position + 1, record)
        return [task] if task is not None else []

    def _finished_in(self, chain: int) -> int:
        """How many points of a chain are finished (always its first ones)."""
        _, direction = CHAINS[chain]
        position = 0
        for frequency in self.spec.sequence(direction):
            if self.spec.index(chain, frequency) not in self.done:
                break
            position += 1
        return position

    def _task(self, chain: int, position: int, previous: Optional[dict] = None) -> Optional[tuple]:
        spec = self.spec
        damper, direction = CHAINS[chain]
        order = spec.sequence(direction)
        if position >= len(order):
            return None
        if previous is None and position > 0:
            previous = self.done[spec.index(chain, order[position - 1])]
        if previous is not None and previous.get("status") == "ok":
            state, phase = previous["state"], previous["phase"]
        else:
            state, phase = rest_state(), 0.0
        frequency = order[position]
        omega = float(spec.omegas[frequency])
        args = (spec.index(chain, frequency), spec.chain_values(damper), omega, spec.base_amplitude(omega),
                spec.settings, state, phase)
        return (chain, position), solve_point, args


def open_frequency_run(model: FmuModel, spec: FrequencySpec, folder: Path, resume: bool, force: bool) -> FrequencyRun:
    """Check the folder and read what it holds; change nothing (see :meth:`FrequencyRun.begin`)."""
    header = {**spec.to_dict(), "fmu": str(model.path), "fmu_guid": model.guid}
    same = tuple(k for k in header if k != "fmu")
    folder, done, start_over = open_folder(folder, HEADER_FILE, header, same, resume, force, "--out",
                                           "frequency response")
    return FrequencyRun(spec, folder, done, header, start_over)


def execute(run: FrequencyRun, backend, progress: Optional[bool] = None) -> None:
    """Run every unfinished point, appending each record to ``points.jsonl`` as it arrives."""
    from tqdm import tqdm

    tasks = run.first_tasks()
    bar = tqdm(total=run.total, initial=len(run.done), unit="pt", desc="frequency response", dynamic_ncols=True,
               disable=(not progress) if progress is not None else None, file=sys.stderr)
    interrupted = True
    with PointStore(run.folder) as store:
        try:
            for _, record in backend.run_tasks(tasks, run.follow):
                store.append(record)
                run.done[record["index"]] = record
                bar.update(1)
            interrupted = False
        finally:
            bar.close()
            backend.close(cancel=interrupted)


def rest_state() -> list[float]:
    """The guess of a chain's first point: everything at rest (``p = q = 0``)."""
    return [0.0] * len(STATE_PARAMETERS)
