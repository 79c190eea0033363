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

A folder ends up with ``frequency_response.json`` (what was asked), ``points.jsonl``,
``frequency_response.nc`` (xarray, units in attributes), ``frequency_response.csv``,
``summary.json`` and the figures ``amplitude.png``, ``power.png``, ``impacts.png``.

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

from .analysis import bands
from .fmu import FmuModel, FmuRunError, Instance
from .steady_state import STATE_PARAMETERS, HarmonicDrive, Settings, SteadyState
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
    "amplitude": ("m", "steady-state amplitude of the main mass, half its peak-to-peak"),
    "rms": ("m", "RMS of the main mass's displacement p over the steady-state orbit"),
    "transmissibility": ("1", "amplitude / base displacement amplitude Y"),
    "impacts_per_cycle": ("1", "impacts (contact onsets, both barriers) per forcing cycle"),
    "V_rms": ("V", "RMS of the impact voltages in steady state (eq. 30, under the voltage model)"),
    "harvested_power": ("W", "mean power into both loads in steady state (harvested_energy / time)"),
    "mean_displacement": ("m", "mean of p over the steady-state orbit"),
    "return_error": ("m", "largest return distance of the verified section (settled points)"),
    "cycles": ("1", "forcing cycles simulated to find and verify the steady state"),
    "newton_iterations": ("1", "Newton iterations spent"),
    "order": ("1", "period of the orbit in forcing periods (0: not settled)"),
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


# -- results ---------------------------------------------------------------------------------------

def build_dataset(spec: FrequencySpec, records: dict, model: FmuModel):
    """The study as an ``xarray.Dataset`` over ``(damper, direction, omega)``; unfinished points
    are NaN (``status`` missing)."""
    import xarray as xr

    count = len(spec.ratios)
    shape = (len(DAMPER_CASES), len(DIRECTIONS), count)
    data = {key: np.full(shape, np.nan) for key in MEASURES}
    settled = np.zeros(shape, dtype=np.int8)
    method = np.full(shape, "missing", dtype=object)
    error = np.full(shape, "", dtype=object)
    for chain, (damper, direction) in enumerate(CHAINS):
        position = (DAMPER_CASES.index(damper), DIRECTIONS.index(direction))
        for frequency in range(count):
            record = records.get(spec.index(chain, frequency))
            if record is None:
                continue
            where = (*position, frequency)
            for key in MEASURES:
                value = record.get(key)
                data[key][where] = np.nan if value is None else value
            data["order"][where] = record.get("order") or 0
            settled[where] = bool(record.get("settled"))
            method[where] = record.get("method") if record["status"] == "ok" else "error"
            error[where] = record.get("error") or ""

    omegas = spec.omegas
    dims = ("damper", "direction", "omega")
    variables = {key: (dims, values, {"units": MEASURES[key][0], "long_name": MEASURES[key][1]})
                 for key, values in data.items()}
    variables["settled"] = (dims, settled, {"units": "1", "long_name": "1: the steady state was found and verified; "
                                                                    "0: the cap on cycles was reached first"})
    variables["method"] = (dims, method.astype(str), {"long_name": "newton, marching, none (not settled), error "
                                                                   "(the FMU rejected the point) or missing"})
    variables["error"] = (dims, error.astype(str), {"long_name": "the FMU's message for a rejected point"})
    differ = directions_differ(data, settled)
    variables["directions_differ"] = (("damper", "omega"), differ.astype(np.int8),
                                      {"units": "1", "long_name": "1: up and down sweeps settled on different orbits "
                                                                  f"(order, impacts per cycle, or amplitude beyond "
                                                                  f"{BAND_TOLERANCE:g} relative)"})
    parameters = {**model.defaults(), **spec.values}
    variables["transmissibility_linear"] = (("omega",), linear_transmissibility(omegas, parameters["M"], parameters["K"],
                                                                                parameters["C"]),
                                            {"units": "1", "long_name": "|X/Y| of the main mass alone (closed form)"})
    coords = {
        "damper": ("damper", list(DAMPER_CASES), {"long_name": "with the damper, or without (gap widened)"}),
        "direction": ("direction", list(DIRECTIONS), {"long_name": "sweep direction in frequency"}),
        "omega": ("omega", omegas, {"units": "rad/s", "long_name": "forcing angular frequency"}),
        "ratio": ("omega", np.array(spec.ratios), {"units": "1", "long_name": "w / sqrt(K/M)"}),
        "base_amplitude": ("omega", np.array([spec.base_amplitude(w) for w in omegas]),
                           {"units": "m", "long_name": "base displacement amplitude Y"}),
    }
    attrs = {
        "title": "piezo-impact damper: frequency response to harmonic base motion",
        "natural_frequency_rad_per_s": spec.natural,
        "excitation": (f"y = Y sin(w t), Y = {spec.amplitude:g} m" if spec.amplitude is not None
                       else f"y = Y sin(w t), Y = A / w^2, A = {spec.acceleration:g} m/s^2"),
        "parameters": json.dumps(spec.values),
        "parameters_not_listed": "the FMU's start values (the nominal case)",
        "without_damper": f"the same FMU with the gap d = {spec.wide_gap:g} m (no impact possible)",
        "settings": json.dumps(asdict(spec.settings)),
        "tolerance_m": "settings.tolerance * Y: the section's return distance max(|dp|, |dp'|/w, |dq|, |dq'|/w)",
        "fmu": str(model.path),
        "fmu_guid": model.guid,
    }
    return xr.Dataset(variables, coords=coords, attrs=attrs)


def directions_differ(data: dict, settled: np.ndarray) -> np.ndarray:
    """``(damper, omega)``: where both directions settled on different orbits."""
    both = (settled[:, 0, :] == 1) & (settled[:, 1, :] == 1)
    amplitude, impacts, order = data["amplitude"], data["impacts_per_cycle"], data["order"]
    with np.errstate(invalid="ignore"):
        apart = np.abs(amplitude[:, 0, :] - amplitude[:, 1, :]) > BAND_TOLERANCE * np.fmax(amplitude[:, 0, :],
                                                                                            amplitude[:, 1, :])
    other = (order[:, 0, :] != order[:, 1, :]) | (impacts[:, 0, :] != impacts[:, 1, :])
    return both & (apart | other)


def summarize(ds) -> dict:
    """What a designer asks: the resonant amplitude with and without the damper, the band where
    the damper lowers it, the best harvested power and where, the jump bands, what did not settle."""
    ratios = ds["ratio"].values
    settled = ds["settled"].values == 1
    amplitude = np.where(settled, ds["amplitude"].values, np.nan)
    power = np.where(settled, ds["harvested_power"].values, np.nan)
    report = {"excitation": ds.attrs["excitation"], "natural_frequency_rad_per_s": ds.attrs["natural_frequency_rad_per_s"],
              "points": int(ds["amplitude"].size), "not_settled": {}, "resonant_amplitude_m": {},
              "damper_helps": {}, "best_harvested_power": {}, "jump_bands": {}}
    for i, damper in enumerate(DAMPER_CASES):
        report["jump_bands"][damper] = bands(ratios, ds["directions_differ"].values[i] == 1)
        for j, direction in enumerate(DIRECTIONS):
            key = f"{damper} the damper, sweep {direction}"
            report["not_settled"][key] = [float(r) for r in ratios[~settled[i, j]]]
            row = amplitude[i, j]
            if np.isfinite(row).any():
                k = int(np.nanargmax(row))
                report["resonant_amplitude_m"][key] = {"amplitude_m": float(row[k]), "at_ratio": float(ratios[k]),
                                                       "transmissibility": float(ds["transmissibility"].values[i, j, k])}
    for j, direction in enumerate(DIRECTIONS):
        with np.errstate(invalid="ignore"):
            helps = amplitude[0, j] < amplitude[1, j]
        report["damper_helps"][direction] = {
            "bands": bands(ratios, helps),
            "peak_ratio_with_over_without": _ratio(np.nanmax(amplitude[0, j]) if np.isfinite(amplitude[0, j]).any()
                                                   else None,
                                                   np.nanmax(amplitude[1, j]) if np.isfinite(amplitude[1, j]).any()
                                                   else None),
        }
        row = power[0, j]
        if np.isfinite(row).any() and np.nanmax(row) > 0:
            k = int(np.nanargmax(row))
            report["best_harvested_power"][direction] = {"power_W": float(row[k]), "at_ratio": float(ratios[k]),
                                                         "amplitude_m": float(amplitude[0, j, k]),
                                                         "impacts_per_cycle": float(ds["impacts_per_cycle"].values[0, j, k])}
    return report


def _ratio(a, b) -> Optional[float]:
    return float(a) / float(b) if a is not None and b else None


def summary_lines(report: dict) -> list[str]:
    """Human-readable lines for :func:`summarize`'s report."""
    def mm(value):
        return f"{1e3 * value:.4g} mm"

    lines = [f"frequency response ({report['excitation']}; w_n = sqrt(K/M) = "
             f"{report['natural_frequency_rad_per_s']:.4g} rad/s; {report['points']} points):"]
    for key, peak in report["resonant_amplitude_m"].items():
        lines.append(f"  peak amplitude {key}: {mm(peak['amplitude_m'])} at w/w_n = {peak['at_ratio']:.4g} "
                     f"(transmissibility {peak['transmissibility']:.4g})")
    for direction, helps in report["damper_helps"].items():
        shown = ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in helps["bands"]) or "nowhere"
        ratio = helps["peak_ratio_with_over_without"]
        lines.append(f"  sweep {direction}: the damper lowers the amplitude at w/w_n {shown}; peak with / without = "
                     f"{'n/a' if ratio is None else f'{ratio:.4g}'}")
    for direction, best in report["best_harvested_power"].items():
        lines.append(f"  best harvested power (sweep {direction}): {1e3 * best['power_W']:.4g} mW at w/w_n = "
                     f"{best['at_ratio']:.4g} ({best['impacts_per_cycle']:.4g} impacts per cycle, amplitude "
                     f"{mm(best['amplitude_m'])})")
    for damper, runs in report["jump_bands"].items():
        if runs:
            lines.append(f"  up and down sweeps differ {damper} the damper at w/w_n "
                         + ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in runs))
    unsettled = {key: values for key, values in report["not_settled"].items() if values}
    for key, values in unsettled.items():
        lines.append(f"  not settled within the cap ({key}): {len(values)} points, at w/w_n "
                     + ", ".join(f"{v:.4g}" for v in values))
    return lines


def tidy_frame(ds):
    """One row per point: damper, direction, frequency and every measure."""
    frame = ds.drop_vars(["directions_differ", "transmissibility_linear"]).to_dataframe().reset_index()
    frame["order"] = frame["order"].astype("Int64")
    return frame


def finish(model: FmuModel, run: FrequencyRun, jobs: int = 1) -> dict:
    """Write the Dataset, the CSV, the summary and the figures (drawn in ``jobs`` processes), after
    return ``{"dataset", "summary", "files"}``."""
    from . import figures
    from .analysis import save_dataset

    ds = build_dataset(run.spec, run.done, model)
    report = summarize(ds)
    rendering = figures.Rendering(figures.frequency_figure_calls(ds, run.folder), jobs)
    files = [run.folder / "frequency_response.nc", run.folder / "frequency_response.csv", run.folder / "summary.json"]
    save_dataset(ds, files[0])
    tidy_frame(ds).to_csv(files[1], index=False)
    files[2].write_text(json.dumps(report, indent=2) + "\n")
    return {"dataset": ds, "summary": report, "files": files + rendering.wait()}


def rest_state() -> list[float]:
    """The guess of a chain's first point: everything at rest (``p = q = 0``)."""
    return [0.0] * len(STATE_PARAMETERS)
