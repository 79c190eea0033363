"""The bifurcation diagram's two sweeps on the engine, recorded as they go, and the FMU's checks.

The sweeps are two chains of tasks of the sweep engine, a frequency a task (:func:`.study.frequency`),
each point's cloud a task of its own (:func:`.study.companions`). Every task is appended to
``points.jsonl`` as it finishes: a frequency's record (``index`` ``j * count + number``, ``j`` 0 for
the sweep up and 1 down, ``number`` the frequency's place in its sweep) holds its point, its
trajectory's record and where its motion goes (``next``); a cloud's (``index`` ``2 * count + j *
count + number``) holds the cloud's records. What was asked goes to ``bifurcation.json``.
``--resume`` goes on from what is recorded: each sweep from the frequency after its last recorded
one, from where that one's motion went, and each cloud not recorded; the points are the same to the
bit (a frequency's march depends on its start alone, a cloud's on its point's start and its seed).

The FMU's checks (:func:`checks`) follow the rule of :mod:`piezo_fmu_harness.starts.fmu_checks`:
every kind of motion the diagram shows (the class, and for an orbit its order and impacts per cycle)
from one of its points, and ``--confirm`` points more drawn at random.

This study reads the simulation core's batch engine besides the FMU (see :mod:`.study`).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict
from pathlib import Path

from ...periodic.band import FrequencySpec
from ...store import Damaged, PointStore, jsonable, open_folder, require, within
from ...wording import counted
from .study import DIRECTIONS, companions, follow, frequency, judged

HEADER_FILE = "bifurcation.json"


def plain(spec: FrequencySpec, device: str) -> dict:
    """What the tasks need of the study (JSON-safe): it is also the header, ``bifurcation.json``."""
    return {"values": spec.values, "settings": asdict(spec.settings), "ratios": list(spec.ratios),
            "natural": spec.natural, "amplitude": spec.amplitude, "acceleration": spec.acceleration, "device": device}


def open_diagram(model, header: dict, folder: Path, resume: bool, force: bool):
    """Check the folder and read its records (:func:`piezo_fmu_harness.store.open_folder`); change
    nothing. Returns ``(folder, records by index, start_over)``."""
    header = {**header, "fmu_guid": model.guid}
    return open_folder(folder, HEADER_FILE, header, tuple(k for k in header if k != "fmu_guid"), resume, force,
                       "--out", "bifurcation diagram", check=record_check(header["ratios"]))


def record_check(ratios: list):
    """The check of a record: a frequency of one of the sweeps, at its ratio, with its point and
    where its motion goes; or a cloud."""
    count = len(ratios)

    def check(record: dict) -> None:
        within(record["index"], 4 * count, "record")
        if record["index"] >= 2 * count:
            require(record, {"cloud": dict})
            require(record["cloud"], {"records": list}, "the cloud's ")
            return
        require(record, {"point": dict, "record": (dict, type(None)), "next": list})
        require(record["point"], {"ratio": float, "start": list, "start_side": float, "periods": int}, "the point's ")
        j, number = divmod(record["index"], count)
        ratio = ratios[number] if j == 0 else ratios[count - 1 - number]
        if not math.isclose(record["point"]["ratio"], ratio, rel_tol=1e-12):
            raise Damaged(f"record {record['index']} is at w/w_n = {record['point']['ratio']:.6g}, this diagram's at "
                          f"{ratio:.6g}: a record of another run")
        if len(record["next"]) != 2:
            raise Damaged(f"'next' is {record['next']!r}, not a state and a side")
    return check


def run(header: dict, backend, folder: Path, done: dict, start_over: bool, progress=None):
    """Both sweeps of the diagram ``header`` asks for (:func:`plain`, with the FMU's ``fmu_guid``) on
    ``backend`` from what ``done`` holds (see the module's text), each finished
    task appended to ``points.jsonl``, with a progress bar on stderr unless ``progress`` is False;
    returns the sweeps (up first), or None when interrupted (Ctrl-C), after saying how to resume."""
    from tqdm import tqdm

    from ...checks import PROG

    count = len(header["ratios"])
    if start_over:
        PointStore(folder).clear()
    (folder / HEADER_FILE).write_text(json.dumps(header, indent=2) + "\n")
    marched = {(DIRECTIONS[r["index"] // count], r["index"] % count): r for r in done.values() if r["index"] < 2 * count}
    clouds = {(DIRECTIONS[(r["index"] - 2 * count) // count], (r["index"] - 2 * count) % count): r["cloud"]
              for r in done.values() if r["index"] >= 2 * count}
    points = {d: [None] * count for d in DIRECTIONS}
    tasks = []
    for d in DIRECTIONS:
        number = 0
        while (d, number) in marched:
            number += 1
        state, side = marched[(d, number - 1)]["next"] if number else ([0.0] * 4, 0.0)
        if number < count:
            tasks.append(((d, number), frequency, (header, d, number, state, side)))
    for (d, number), result in marched.items():
        if result["record"] is None:
            points[d][number] = result["point"]
        elif (d, number) in clouds:
            points[d][number] = judged(result["point"], result["record"], clouds[(d, number)])
        else:
            tasks.append(((d, number, "cloud"), companions,
                          (header, d, number, result["point"]["start"], result["point"]["start_side"])))
    finished = sum(p is not None for d in DIRECTIONS for p in points[d])
    bar = tqdm(total=2 * count, initial=finished, unit="pt", desc="bifurcation", dynamic_ncols=True,
               disable=(not progress) if progress is not None else None, file=sys.stderr)
    try:
        with PointStore(folder) as store:
            for tag, result in backend.run_tasks(tasks, follow(header)):
                d, number = tag[:2]
                j = DIRECTIONS.index(d)
                if len(tag) == 3:
                    store.append({"index": 2 * count + j * count + number, "cloud": jsonable(result)})
                    points[d][number] = judged(marched[(d, number)]["point"], marched[(d, number)]["record"], result)
                else:
                    record = jsonable({"index": j * count + number, **result})
                    store.append(record)
                    marched[(d, number)] = record
                    if result["record"] is not None:
                        continue  # judged once its cloud is in
                    points[d][number] = record["point"]
                bar.update(1)
    except KeyboardInterrupt:
        bar.close()
        backend.close(cancel=True)
        print(f"\n{PROG} bifurcation: interrupted; {sum(p is not None for d in DIRECTIONS for p in points[d])} of "
              f"{counted(2 * count, 'point')} are saved in {folder / 'points.jsonl'}; run the same command with --resume to "
              "finish", file=sys.stderr)
        return None
    bar.close()
    return [{"direction": d, "points": points[d]} for d in DIRECTIONS]


def checks(spec: FrequencySpec, sweeps: list[dict], backend, count: int, seed: int, progress=None) -> list[dict]:
    """The FMU's checks of a sample of points (:func:`piezo_fmu_harness.starts.fmu_checks.confirm`):
    every kind of motion (the class, and for an orbit its order and impacts per cycle) from the point
    that reached it soonest, and ``count`` more drawn at random (seeded), among the points whose start
    has the impact mass free (the FMU starts only so)."""
    from piezo_fmu.solver.batch import HarmonicHold, damper, tracks

    from ...starts.fmu_checks import confirm

    width = len(spec.ratios)
    starts = {}
    for j, sweep in enumerate(sweeps):
        for k, p in enumerate(sweep["points"]):
            if p["status"] == "ok" and p["start_side"] == 0.0:
                kind = (p["motion"], p["order"], p["impacts_per_cycle"] if p["motion"] == "periodic" else None)
                starts[j * width + k] = {"index": j * width + k, "group": k if j == 0 else width - 1 - k,
                                         "periods": p["periods"], "attractor": kind, "motion": p["motion"]}
    params = damper(spec.values)

    def make(chosen: list[int]) -> list[dict]:
        payloads = []
        for index in chosen:
            j, k = divmod(index, width)
            p = sweeps[j]["points"][k]
            drive = HarmonicHold(p["omega"], p["amplitude_Y"], 0.0, spec.settings.samples)
            payloads.append({"index": index, "values": spec.values, "omega": p["omega"],
                             "amplitude": p["amplitude_Y"], "samples": spec.settings.samples, "start": p["start"],
                             "periods": p["periods"], "cap": spec.settings.max_cycles,
                             "track": tracks(params, drive, [p["start"]], [0], [p["periods"]])[0],
                             "attractors": [{**p["attractor"], "id": 0, "group": 0}], "study": 0})
        return payloads

    results = confirm(backend, starts, make, count, seed, what="bifurcation", progress=progress)
    for result in results:
        j, k = divmod(result["index"], width)
        p = sweeps[j]["points"][k]
        result.update(direction=sweeps[j]["direction"], ratio=p["ratio"], motion=p["motion"])
    return results
