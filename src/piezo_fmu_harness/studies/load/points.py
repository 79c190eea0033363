"""The load sweep's points on the engine, kept as they finish: what was asked goes to ``loads.json``
(the models, the loads, the duration, the step, the parameters changed, the FMU's GUID), each finished
point to ``points.jsonl``, and ``--resume`` runs only the points not recorded
(:func:`piezo_fmu_harness.store.open_folder`).

The points are numbered model by model, each model's loads in increasing order and then the
paper's load; they run in another order (model 2's lowest loads first, the costliest).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ...fmu import METRIC_OUTPUTS, OPTIONAL_METRICS, FmuModel
from ...store import Damaged, PointStore, numbers, open_folder, require, within

HEADER_FILE = "loads.json"


def points(models, loads, nominal_load: float, overrides: dict) -> list[tuple[int, int, dict]]:
    """Every point as ``(index, model, values)``: each model's loads, then the paper's load."""
    found = []
    for m in models:
        for r in (*loads, nominal_load):
            found.append((len(found), m, {**overrides, "voltage_model": m, "R_load": r}))
    return found


def open_loads(model: FmuModel, header: dict, folder: Path, todo: list, resume: bool, force: bool):
    """Check the folder and read its points (:func:`piezo_fmu_harness.store.open_folder`); change
    nothing. Returns ``(folder, finished records by index, start_over)``."""
    header = {**header, "fmu_guid": model.guid}
    return open_folder(folder, HEADER_FILE, header, tuple(k for k in header if k != "fmu_guid"), resume, force,
                       "--out", "load sweep", check=record_check(todo))


def record_check(todo: list):
    """The check of a recorded point: one of the sweep's, at its model and load, with its status and
    metrics (numbers or null)."""
    def check(record: dict) -> None:
        require(record, {"values": dict, "status": str})
        within(record["index"], len(todo))
        _, m, values = todo[record["index"]]
        given = record["values"]
        if given.get("voltage_model") != m or not math.isclose(given.get("R_load", math.nan), values["R_load"],
                                                               rel_tol=1e-12):
            raise Damaged(f"point {record['index']} was run at voltage_model = {given.get('voltage_model')}, "
                          f"R_load = {given.get('R_load')}, this sweep's at {m} and {values['R_load']:g}: a record "
                          "of another run")
        numbers(record, (*METRIC_OUTPUTS, *OPTIONAL_METRICS, "seconds", "cpu_seconds"))
    return check


def execute(backend, todo: list, folder: Path, done: dict, start_over: bool, header: dict, stop_time: float,
            step: float, progress) -> None:
    """Run the points of ``todo`` not in ``done`` on ``backend``, the costliest first, appending each
    record to ``points.jsonl`` as it arrives (a progress bar on a terminal unless ``progress`` is
    False)."""
    from tqdm import tqdm

    if start_over:
        PointStore(folder).clear()
    (folder / HEADER_FILE).write_text(json.dumps(header, indent=2) + "\n")
    # Model 2's cost grows as 1/R: its lowest loads go first so the workers finish together.
    remaining = sorted((item for item in todo if item[0] not in done), key=lambda item: (-item[1], item[2]["R_load"]))
    bar = tqdm(total=len(todo), initial=len(todo) - len(remaining), unit="pt", desc="load sweep", dynamic_ncols=True,
               disable=(not progress) if progress is not None else None, file=sys.stderr)
    interrupted = True
    try:
        with PointStore(folder) as store:
            for _, record in backend.run([(m, index, values, stop_time, step) for index, m, values in remaining]):
                store.append(record)
                done[record["index"]] = record
                bar.update(1)
        interrupted = False
    finally:
        bar.close()
        backend.close(cancel=interrupted)
