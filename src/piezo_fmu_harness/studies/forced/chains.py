"""The frequency response: the damper shaken at its base, swept up and down in
frequency, with and without the damper, through the FMU.

The base moves as ``y = Y sin(w t)``, ``Y`` given directly or as ``A / w^2`` for an acceleration
amplitude ``A``; ``w`` runs over ``count`` evenly spaced values between ``ratio_min`` and
``ratio_max`` times ``sqrt(K/M)``. At each frequency the steady state is found by shooting and
verified by simulation (:mod:`piezo_fmu_harness.periodic.steady_state`), starting from the previous frequency's final
state, so that a sweep follows one branch of coexisting orbits until it ends (a jump). Four chains
run: with and without the damper, each up and down. Without the damper, the gap is widened until
the impact mass cannot reach a barrier, as for Fig. 3a.

The chains are independent, and each is a sequence of dependent points: a point is one task on
the sweep engine (process pool, Dask or in-process), and the next point of its chain is
submitted as soon as it returns, so four chains keep two cores busy. Each finished point is
appended to ``points.jsonl``; ``--resume`` continues every chain from its last finished point.

A folder ends up with ``frequency_response.json`` (what was asked), ``points.jsonl``, and the
results that :mod:`piezo_fmu_harness.studies.forced.results` writes: ``frequency_response.nc`` (xarray,
units in attributes), ``frequency_response.csv``, ``summary.json`` and the figures
``amplitude.png``, ``power.png``, ``impacts.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ...fmu import FmuModel
from ...periodic.band import FrequencySpec, rest_state, solve_point
from ...store import Damaged, PointStore, numbers, open_folder, require, vector, within

HEADER_FILE = "frequency_response.json"
#: The four chains, in the order their first points are submitted (the costly ones first).
CHAINS = (("with", "up"), ("with", "down"), ("without", "up"), ("without", "down"))
DIRECTIONS = ("up", "down")
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
    "lyapunov_exponent": ("1/period", "largest Lyapunov exponent of a motion that is not periodic, per forcing period"),
    "modulation": ("1", "amplitude modulation of a motion that is not periodic: (largest - smallest) / largest"),
    "seconds": ("s", "wall time of the point in its worker"),
}


# -- one point, in a worker ------------------------------------------------------------------------


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
                                           "frequency response", check=record_check(spec))
    return FrequencyRun(spec, folder, done, header, start_over)


def record_check(spec: FrequencySpec):
    """The check of a recorded point (:func:`piezo_fmu_harness.store.open_folder`): one of the
    study's points, at its frequency, with its status, its measures (numbers or null) and, when
    it settled, the state and phase the next point of its chain starts from."""
    count = len(spec.ratios)

    def check(record: dict) -> None:
        require(record, {"omega": float, "status": str})
        within(record["index"], len(CHAINS) * count)
        omega = float(spec.omegas[record["index"] % count])
        if not math.isclose(record["omega"], omega, rel_tol=1e-12):
            raise Damaged(f"point {record['index']} is at w = {record['omega']:.6g} rad/s, this study's at "
                          f"{omega:.6g}: a record of another run")
        numbers(record, [key for key in MEASURES if key != "unstable_orbits"])
        require(record, {"unstable_orbits": (list, type(None)), "multipliers": (list, type(None))}, optional=True)
        if record["status"] == "ok":
            vector(record, "state", len(rest_state()))
            require(record, {"phase": float})
    return check


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
