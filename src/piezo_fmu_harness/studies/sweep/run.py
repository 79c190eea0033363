"""Running sweeps: the folder of each sweep, the incremental run, and the results.

A sweep folder ``OUT`` ends up with:

- ``sweep.json``: what was asked (axes, fixed values, duration, step) and the FMU's GUID;
- ``points.jsonl``: one line per finished point, appended and flushed as it finishes;
- ``sweep.nc``: the xarray Dataset (metrics over the axes, perfectibility, status);
- ``sweep.csv``: the same as a tidy table, one row per point;
- ``zones.json``: our vibratory, energy and design zones and how the paper's zone fares;
- ``DI.png`` (``DI_ls.png`` with ``--damping ls``, and ``damping_measures.png``, the two side by
  side), ``V_rms.png``, ``P_ave.png``, ``perfectibility.png``: contours with the zones. A preset
  set draws the paper's Figs. 4-9 instead, whose panels are the same contours.

Several sweeps (a preset set) share one backend, so its workers start once and stay busy.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from ...datasets import csv_frame, save_dataset, units_of
from ...drawing import Rendering
from ...fmu import METRIC_OUTPUTS, OPTIONAL_METRICS, FmuModel
from ...spec import SweepSpec
from ...store import SPEC_FILE, Damaged, PointStore, numbers, open_folder, require, within
from . import analysis, figures


@dataclass
class SweepRun:
    """One sweep and its folder; ``done`` holds the records already finished."""

    spec: SweepSpec
    folder: Path
    done: dict = field(default_factory=dict)
    header: dict = field(default_factory=dict)  # what sweep.json will say
    start_over: bool = False  # discard the points recorded in the folder

    def begin(self) -> None:
        """Commit the folder to this sweep: write ``sweep.json`` (and drop old points if
        starting over). Called only once every check of every sweep has passed."""
        if self.start_over:
            self.store.clear()
        (self.folder / SPEC_FILE).write_text(json.dumps(self.header, indent=2) + "\n")

    @property
    def store(self) -> PointStore:
        return PointStore(self.folder)

    def todo(self) -> list[tuple[int, dict]]:
        return [(index, self.spec.values_at(point)) for index, point in self.spec.points()
                if index not in self.done]


def open_sweep(model: FmuModel, spec: SweepSpec, folder: Path, resume: bool, force: bool,
               option: str = "--out") -> SweepRun:
    """Check the folder of one sweep and read what it holds; change nothing (see
    :meth:`SweepRun.begin`).

    Without ``resume`` a folder that already holds finished points is refused unless ``force``
    (which starts over); with ``resume`` it must hold this same sweep of this same FMU.
    """
    header = {**spec.to_dict(), "fmu": str(model.path), "fmu_guid": model.guid}
    folder, done, start_over = open_folder(folder, SPEC_FILE, header, ("axes", "fixed", "stop_time", "step"),
                                           resume, force, option, "sweep", check=record_check(spec))
    return SweepRun(spec, folder, done, header, start_over)


def record_check(spec: SweepSpec):
    """The check of a recorded point (:func:`piezo_fmu_harness.store.open_folder`): one of this
    sweep's points, at its values, with its status and metrics (numbers or null)."""
    expected = dict(spec.points())

    def check(record: dict) -> None:
        require(record, {"values": dict, "status": str})
        within(record["index"], spec.size)
        point = expected[record["index"]]
        if any(record["values"].get(k) != v for k, v in point.items()):
            raise Damaged(f"point {record['index']} was run at {record['values']}, not at this sweep's {point}: a "
                          "record of another run")
        numbers(record, (*METRIC_OUTPUTS, *OPTIONAL_METRICS, "seconds", "cpu_seconds"))
    return check


def execute(runs: list[SweepRun], backend, progress: Optional[bool] = None) -> None:
    """Run every unfinished point of ``runs`` on ``backend``, appending each record to its
    sweep's ``points.jsonl`` as soon as it arrives. ``progress=None`` shows a bar on a terminal."""
    from tqdm import tqdm

    todo, stores = [], []
    for number, run in enumerate(runs):
        stores.append(run.store.open())
        todo.extend((number, index, values, run.spec.stop_time, run.spec.step)
                    for index, values in run.todo())
    total = sum(run.spec.size for run in runs)
    finished = total - len(todo)
    bar = tqdm(total=total, initial=finished, unit="pt", desc="sweep", dynamic_ncols=True,
               disable=(not progress) if progress is not None else None, file=sys.stderr)
    interrupted = True
    try:
        for number, record in backend.run(todo):
            stores[number].append(record)
            runs[number].done[record["index"]] = record
            bar.update(1)
        interrupted = False
    finally:
        bar.close()
        for store in stores:
            store.close()
        backend.close(cancel=interrupted)


def write_results(model: FmuModel, runs: list[SweepRun], names: list[str], panels: Optional[dict], out: Path,
                  quantile: float = analysis.DEFAULT_ZONE_QUANTILE, damping: str = analysis.DEFAULT_DAMPING,
                  jobs: int = 1, timings: Optional[dict] = None) -> dict:
    """Write every sweep's results (:func:`finish`) and their figures, drawn in ``jobs`` processes;
    with ``panels`` (a preset set: letter -> sweep name), the paper's Figs. 4-9 and a combined
    ``zones.json`` in ``out`` instead of each sweep's contours. Returns the results by name;
    ``timings``, if given, receives the seconds spent building the datasets and until every file
    and figure is written (the figures are drawn in forked processes while the files are written)."""
    begin = time.perf_counter()
    results = {name: finish(model, run, quantile, damping) for name, run in zip(names, runs)}
    if panels:
        calls = figures.paper_figure_calls({letter: (results[name]["dataset"], results[name]["masks"],
                                                     results[name]["paper_zone"]) for letter, name in panels.items()},
                                           out, figures.Sheets())
        calls += [call for result in results.values() for call in result["figures"]
                  if call[0] is figures.damping_measures_figure]
        combined = {name: results[name]["zones"] for name in panels.values()}
        (Path(out) / "zones.json").write_text(json.dumps(combined, indent=2) + "\n")
    else:
        calls = [call for result in results.values() for call in result["figures"]]
    built = time.perf_counter()
    rendering = Rendering(calls, jobs)
    for result in results.values():
        result["write"]()
    written = time.perf_counter()
    rendering.wait()
    if timings is not None:
        timings.update(datasets_s=built - begin, files_s=written - built, figures_s=time.perf_counter() - built,
                       figures=len(calls))
    return results


def finish(model: FmuModel, run: SweepRun, quantile: float = analysis.DEFAULT_ZONE_QUANTILE,
           damping: str = analysis.DEFAULT_DAMPING) -> dict:
    """The results of one finished sweep, not yet written: ``{"dataset", "zones", "masks",
    "paper_zone", "files", "figures"}``. ``files`` are written by ``write`` (a function of no
    argument, under the key ``write``); ``figures`` are the calls that draw the contours (and
    Eq. 29's DI beside DI_ls when the sweep ranks by DI_ls), for :class:`piezo_fmu_harness.drawing.Rendering`."""
    ds = analysis.build_dataset(run.spec, run.done, model, damping)
    zones = analysis.zones_report(ds, quantile)
    masks = {metric: analysis.top_zone(ds, metric, quantile)[0] for metric in analysis.zone_kinds(ds)}
    ds.attrs["zones"] = json.dumps(zones)
    files = [run.folder / "sweep.nc", run.folder / "sweep.csv", run.folder / "zones.json"]

    def write() -> None:
        save_dataset(ds, files[0])
        csv_frame(analysis.tidy_frame(ds, quantile), units_of(ds)).to_csv(files[1], index=False)
        files[2].write_text(json.dumps(zones, indent=2) + "\n")

    paper_zone = {name: analysis.PAPER_ZONES[name] for name in ds["DI"].dims if name in analysis.PAPER_ZONES}
    sheets = figures.Sheets()
    calls = figures.sweep_figure_calls(ds, masks, paper_zone or None, run.folder, sheets)
    if damping != analysis.DEFAULT_DAMPING and len(ds["DI"].dims) == 2:
        calls.append((figures.damping_measures_figure, sheets, ds, quantile, run.folder / "damping_measures.png"))
    return {"dataset": ds, "zones": zones, "masks": masks, "paper_zone": paper_zone or None, "files": files,
            "write": write, "figures": calls}


def display(ds):
    """A formatter ``(name, lo, hi=None) -> text`` in the paper's units for this dataset:
    ``x1 0-25 mm``, ``m = 0.2 kg``, ``DI = 0.63 cm/s``."""
    def show(name: str, lo: float, hi: float | None = None) -> str:
        if name in figures.METRIC_DISPLAY:
            factor, unit, _ = figures.METRIC_DISPLAY[name]
        else:
            factor, unit = figures.axis_scale(ds[name].attrs.get("units", "") if name in ds else "")
        unit = "" if unit in ("", "1") else f" {unit}"
        if hi is None or lo == hi:
            return f"{name} = {lo * factor:.4g}{unit}"
        return f"{name} {lo * factor:.4g}-{hi * factor:.4g}{unit}"
    return show
