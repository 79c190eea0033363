"""Basins of attraction (issue 23): which motion the machine reaches from where it starts, at one
frequency.

A grid of initial states ``p0`` against ``p0'``, the impact mass at rest in the middle of the gap
(``q0 = p0``, ``q0' = 0``), the base starting at phase 0. Each start is a task of the sweep engine:
its steady state is found as the frequency response finds it
(:mod:`piezo_fmu_harness.periodic.steady_state`), so it ends on a stable orbit (verified, its
multipliers inside the unit circle) or on a motion that is not periodic, classified. Each finished
start is appended to ``points.jsonl``; ``--resume`` runs only the others.

The attractors are the distinct end motions: stable orbits by order, impacts per cycle and
amplitude (within :data:`SAME` relative), motions that are not periodic by their class. The shares
of the grid that end on each answer "how likely is the good orbit?".

Files: ``basins.nc`` (the attractor of each start on ``p0 x dp0``, and the attractors on their own
dimension), ``basins.csv``, ``summary.json``, ``basins.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ...periodic.band import solve_point
from ...periodic.steady_state import Settings
from ...store import PointStore, open_folder

HEADER_FILE = "basins.json"
#: Two stable orbits of the same order and impacts are the same attractor when their amplitudes
#: agree within this (relative).
SAME = 1e-3
#: The default grid: ``p0`` and ``p0'/w`` each from -2 to 2 times the main mass's linear amplitude.
DEFAULT_SPAN, DEFAULT_COUNT = 2.0, 15


@dataclass(frozen=True)
class BasinSpec:
    """One basin map (SI)."""

    ratio: float
    omega: float
    amplitude: float
    values: dict
    p0: tuple       # (lo, hi, count), m
    dp0: tuple      # (lo, hi, count), m/s
    settings: Settings = field(default_factory=Settings)

    def grid(self) -> list[tuple[int, float, float]]:
        p0 = np.linspace(*self.p0[:2], int(self.p0[2]))
        dp0 = np.linspace(*self.dp0[:2], int(self.dp0[2]))
        return [(i * len(dp0) + j, float(p), float(v)) for i, p in enumerate(p0) for j, v in enumerate(dp0)]

    def to_dict(self) -> dict:
        return {**asdict(self), "settings": asdict(self.settings)}


def settle(instance, spec: dict, index: int, p0: float, dp0: float) -> dict:
    """One start's end motion (a task)."""
    record = solve_point(instance, index, spec["values"], spec["omega"], spec["amplitude"],
                         Settings(**spec["settings"]), [p0, dp0, p0, 0.0], 0.0)
    record.update(p0=p0, dp0=dp0)
    record.pop("sections", None)
    return record


def open_basins(model, spec: BasinSpec, folder: Path, resume: bool, force: bool):
    header = {**spec.to_dict(), "fmu_guid": model.guid}
    return open_folder(folder, HEADER_FILE, header, tuple(header), resume, force, "--out", "basin map")


def execute(spec: BasinSpec, folder: Path, done: dict, start_over: bool, header_text: str, backend) -> dict:
    """Run every start not yet in ``done``, appending each record as it arrives."""
    if start_over:
        PointStore(folder).clear()
    (folder / HEADER_FILE).write_text(header_text)
    plain = {"values": spec.values, "omega": spec.omega, "amplitude": spec.amplitude,
             "settings": asdict(spec.settings)}
    tasks = [(index, settle, (plain, index, p0, dp0)) for index, p0, dp0 in spec.grid() if index not in done]
    with PointStore(folder) as store:
        for _, record in backend.run_tasks(tasks):
            store.append(record)
            done[record["index"]] = record
    return done


def attractors(records: list[dict]) -> tuple[list[dict], list[int]]:
    """The distinct end motions and, for each record, the index of its attractor."""
    found: list[dict] = []
    labels = []
    for record in records:
        if record.get("status") != "ok":
            key = {"kind": "error", "motion": "error"}
        elif record["settled"]:
            key = {"kind": "stable orbit", "motion": "periodic", "order": record["order"],
                   "impacts_per_cycle": round(record["impacts_per_cycle"], 6), "amplitude": record["amplitude"],
                   "max_multiplier": record["max_multiplier"]}
        else:
            key = {"kind": "not periodic", "motion": record.get("motion", "unclassified"),
                   "amplitude": record["amplitude"]}
        for k, attractor in enumerate(found):
            if attractor["kind"] == key["kind"] and attractor["motion"] == key["motion"] and (
                    key["kind"] != "stable orbit" or (attractor["order"] == key["order"]
                                                      and attractor["impacts_per_cycle"] == key["impacts_per_cycle"]
                                                      and abs(attractor["amplitude"] - key["amplitude"])
                                                      <= SAME * attractor["amplitude"])):
                attractor["starts"] += 1
                labels.append(k)
                break
        else:
            found.append({**key, "starts": 1})
            labels.append(len(found) - 1)
    for attractor in found:
        attractor["share"] = attractor["starts"] / len(records)
    return found, labels


def write(spec: BasinSpec, done: dict, folder: Path) -> dict:
    import xarray as xr

    from ...datasets import save_dataset
    from .figure import draw

    grid = spec.grid()
    records = [done[index] for index, _, _ in grid]
    found, labels = attractors(records)
    shape = (int(spec.p0[2]), int(spec.dp0[2]))
    p0 = np.linspace(*spec.p0[:2], shape[0])
    dp0 = np.linspace(*spec.dp0[:2], shape[1])
    names = [_name(a) for a in found]
    ds = xr.Dataset(
        {"attractor": (("p0", "dp0"), np.array(labels).reshape(shape),
                       {"long_name": "index of the motion each start ends on (attractor_name)"}),
         "amplitude": (("p0", "dp0"), np.array([r.get("amplitude", np.nan) for r in records]).reshape(shape),
                       {"units": "m", "long_name": "amplitude of the end motion"}),
         "attractor_name": (("attractor",), np.array(names, dtype=str), {}),
         "attractor_share": (("attractor",), np.array([a["share"] for a in found]),
                             {"units": "1", "long_name": "share of the starts that end on it"})},
        coords={"p0": ("p0", p0, {"units": "m", "long_name": "initial displacement of the main mass"}),
                "dp0": ("dp0", dp0, {"units": "m/s", "long_name": "initial velocity of the main mass"})},
        attrs={"title": "piezo-impact damper: basins of attraction", "ratio": spec.ratio, "omega_rad_per_s": spec.omega,
               "base_amplitude_m": spec.amplitude, "start": "q0 = p0, q0' = 0, base phase 0",
               "parameters": json.dumps(spec.values)})
    save_dataset(ds, folder / "basins.nc")
    ds.drop_dims("attractor").to_dataframe().reset_index().to_csv(folder / "basins.csv", index=False)
    report = {"ratio": spec.ratio, "starts": len(records), "attractors": [{**a, "name": n} for a, n in zip(found, names)]}
    (folder / "summary.json").write_text(json.dumps(report, indent=2) + "\n")
    draw(ds, folder / "basins.png")
    return report


def _name(attractor: dict) -> str:
    if attractor["kind"] == "stable orbit":
        return (f"order {attractor['order']}, {attractor['impacts_per_cycle']:g} impacts/cycle, "
                f"{1e3 * attractor['amplitude']:.3g} mm")
    if attractor["kind"] == "error":
        return "refused by the FMU"
    return f"{attractor['motion']} (not periodic)"
