"""The batch engine against marching through the FMU (issue 27), measured side by side in one run.

    python benchmarks/bench_batch.py [--starts N] [--fmu-starts K] [--periods P] [--studies] [--jobs J]

1. **Throughput.** ``N`` random starts at 1.2 sqrt(K/M) (the nominal damper, ``Y`` = 1 mm, 64 hold
   steps a period; ``p0`` and ``p0'/w`` within two linear amplitudes, the impact mass at rest in the
   middle) marched ``P`` periods on the batch engine (numpy on the CPU), and the first ``K`` of them
   marched ``P`` periods through the FMU (the harness's drive, fmpy); start-periods per second of
   each, and their ratio, ``speedup`` (target: >= 50 on 2 cores). On a machine with CuPy and a GPU,
   the same starts on the GPU (and how far its sections end from the CPU's), and 10 times as many.
2. **Agreement.** The ``K`` starts are taken to where they go on the batch engine (the rule of
   ``piezo_fmu.solver.batch.settle``), and the FMU is marched from each until it shows which of
   those attractors it reaches (``piezo_fmu_harness.periodic.confirm``): ``agree`` is true when no
   FMU label differs from the batch engine's while their trajectories were together;
   ``agreeing`` counts the equal labels, ``parted`` the starts whose FMU trajectory left the batch
   engine's in a chaotic transient before the batch engine's answer was known.
3. With ``--studies``: the studies that march many starts, through the command line, timed: the
   201 x 201 basin map at 1.2 sqrt(K/M) (target: 5 minutes on 2 cores), the default bifurcation
   diagram (200 frequencies up and down; target: 30 s) and the default fractions (61 frequencies x
   500 starts; target: 10 minutes).

Prints one JSON object. The load average before the run is part of it: other programs on the cores
slow every figure.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))  # the packages, when not installed

from piezo_fmu import Parameters  # noqa: E402
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, SettleSettings, describe, device_error, settle  # noqa: E402
from piezo_fmu_harness import cli  # noqa: E402
from piezo_fmu_harness.fmu import FmuModel, Instance, default_fmu_path, discard  # noqa: E402
from piezo_fmu_harness.periodic.band import linear_transmissibility  # noqa: E402
from piezo_fmu_harness.periodic.confirm import fmu_label  # noqa: E402
from piezo_fmu_harness.periodic.drive import HarmonicDrive  # noqa: E402

W_N = math.sqrt(1000.0)
RATIO, Y = 1.2, 1e-3
#: The damper as the studies run it: the circuit one-way at the load near the optimum.
VALUES = {"voltage_model": 1, "R_load": 3.59e6}


def starts(count: int, omega: float) -> np.ndarray:
    span = 2.0 * Y * float(linear_transmissibility(omega, 1.0, 1000.0, 0.1))
    rng = np.random.default_rng(2026)
    p0 = rng.uniform(-span, span, count)
    return np.stack([p0, rng.uniform(-span * omega, span * omega, count), p0, np.zeros(count)], axis=1)


def batch_rate(states: np.ndarray, drive: HarmonicHold, periods: int, device: str, keep: list | None = None) -> dict:
    ens = Ensemble(Parameters(**VALUES), drive, states, device=device)
    ens.advance(1)  # first touch: imports, device kernels
    begin = time.perf_counter()
    record = ens.advance(periods)
    wall = time.perf_counter() - begin
    if keep is not None:
        keep.append(record)
    return {"device": device, "starts": len(states), "periods": periods, "wall_s": wall,
            "start_periods_per_s": len(states) * periods / wall}


def same_motion(cpu: dict, gpu: dict) -> dict:
    """How far the GPU's sections are from the CPU's, the same starts marched the same periods, and
    how many starts made the same contact onsets in every period."""
    gap = np.abs(cpu["sections"] - gpu["sections"]).max(axis=(0, 2))
    onsets = (cpu["impacts"] == gpu["impacts"]).all(axis=0)
    return {"max_section_difference_m": float(gap.max()), "median_section_difference_m": float(np.median(gap)),
            "starts_within_1e-9_m": int((gap <= 1e-9).sum()), "starts_same_onsets": int(onsets.sum()),
            "starts": int(gap.size)}


def fmu_rate(instance: Instance, states: np.ndarray, omega: float, periods: int) -> dict:
    values = {**instance.model.defaults(), **VALUES}
    drive = HarmonicDrive(instance, values, omega, Y, 64)
    wall = 0.0
    for x in states:
        drive.start(x, 0.0)
        begin = time.perf_counter()
        drive.advance(periods)
        wall += time.perf_counter() - begin
    return {"starts": len(states), "periods": periods, "wall_s": wall,
            "start_periods_per_s": len(states) * periods / wall}


def agreement(instance: Instance, states: np.ndarray, omega: float) -> dict:
    """Where the starts go on the batch engine, and where the FMU marched from them goes; a start
    whose FMU trajectory left the batch engine's before the batch engine's answer was known (a
    chaotic transient: ``piezo_fmu_harness.periodic.confirm``) counts as parted, not as agreeing."""
    from piezo_fmu.solver.batch import tracks
    from piezo_fmu_harness.periodic.attractors import merge

    params, drive = Parameters(**VALUES), HarmonicHold(omega, Y)
    settled = settle(params, drive, states, settings=SettleSettings())
    records, attractors = settled.records()
    for index, record in enumerate(records):
        record.update(index=index, group=0)
    found, labelled = merge([{"starts": records, "attractors": attractors}], [(omega, Y)])
    listed = [{**a, "id": k} for k, a in enumerate(found)]
    values = {**instance.model.defaults(), **VALUES}
    periods = [labelled[i]["periods"] for i in range(len(states))]
    paths = tracks(params, drive, states, [0] * len(states), periods)
    verdicts = []
    for index, x in enumerate(states):
        fmu = fmu_label(instance, values, omega, Y, 64, x, periods[index], listed, paths[index])
        same = fmu["attractor"] == labelled[index]["attractor"]
        parted = fmu["diverged_at"] is not None and fmu["diverged_at"] <= periods[index]
        verdicts.append("agrees" if same else "parted" if parted else "disagrees")
    return {"agree": "disagrees" not in verdicts, "agreeing": verdicts.count("agrees"),
            "parted": verdicts.count("parted"), "disagreeing": verdicts.count("disagrees"), "checked": len(verdicts),
            "batch_attractors": [describe(a)["kind"] for a in settled.attractors]}


def studies(jobs: int) -> dict:
    timed = {}
    runs = {"basins_201x201": ["basins", "--ratio", "1.2", "--grid", "201"],
            "bifurcation_default": ["bifurcation"],
            "fractions_default": ["fractions"]}
    for name, argv in runs.items():
        with tempfile.TemporaryDirectory() as out:
            begin = time.perf_counter()
            status = cli.main([*argv, "--jobs", str(jobs), "--out", out, "--force"]
                              + (["--no-progress"] if argv[0] != "bifurcation" else []))
            timed[name] = {"wall_s": time.perf_counter() - begin, "exit_status": status,
                           "summary": json.loads((Path(out) / "summary.json").read_text()) if status == 0 else None}
            summary = timed[name]["summary"] or {}
            timed[name]["fmu_checks"] = {k: v for k, v in summary.get("fmu_checks", {}).items()
                                         if k in ("checked", "agree", "parted", "disagree")}
            timed[name].pop("summary")
    return timed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=10_000)
    parser.add_argument("--fmu-starts", type=int, default=8)
    parser.add_argument("--periods", type=int, default=20)
    parser.add_argument("--studies", action="store_true")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    omega = RATIO * W_N
    drive = HarmonicHold(omega, Y)
    states = starts(args.starts, omega)
    model = FmuModel(default_fmu_path())
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        fmu = fmu_rate(instance, states[:args.fmu_starts], omega, args.periods)
        marched: list = []
        cpu = batch_rate(states, drive, args.periods, "cpu", marched)
        small = batch_rate(states[:args.fmu_starts], drive, args.periods, "cpu")
        report = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average_before": load,
                  "fmu": fmu, "batch_cpu": cpu, "batch_cpu_same_starts_as_fmu": small,
                  "speedup": cpu["start_periods_per_s"] / fmu["start_periods_per_s"],
                  "speedup_same_starts": small["start_periods_per_s"] / fmu["start_periods_per_s"]}
        report.update(agreement(instance, states[:args.fmu_starts], omega))
        if device_error("gpu") is None:
            gpu = batch_rate(states, drive, args.periods, "gpu", marched)
            big = batch_rate(starts(10 * args.starts, omega), drive, args.periods, "gpu")
            report["batch_gpu"] = gpu
            report["batch_gpu_10x"] = big
            report["gpu_against_cpu"] = same_motion(*marched)
            report["gpu_speedup"] = gpu["start_periods_per_s"] / fmu["start_periods_per_s"]
            report["gpu_speedup_10x"] = big["start_periods_per_s"] / fmu["start_periods_per_s"]
        else:
            report["batch_gpu"] = None
            report["gpu"] = device_error("gpu")
    finally:
        instance.free()
        discard(unzipdir)
    if args.studies:
        report["studies"] = studies(args.jobs)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
