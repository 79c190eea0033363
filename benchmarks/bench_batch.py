"""The compiled kernel against the FMU, side by side in one run.

    python benchmarks/bench_batch.py [--fmu-starts K] [--studies] [--jobs J]

1. **Throughput against the batch size.** Random starts at 1.2 sqrt(K/M) (the nominal damper,
   ``Y`` = 1 mm, 64 hold steps a period; ``p0`` and ``p0'/w`` within two linear amplitudes, the
   impact mass at rest in the middle) marched on the compiled kernel (every core), 1, 100, 10,000
   and 100,000 starts, each for about 200,000 start-periods; the first ``K`` of them through the FMU
   (the harness's drive, fmpy). ``speedup``: the kernel at 10,000 starts over the FMU (target >= 50);
   ``single``: the kernel at 1 start over the FMU (target >= 200); the kernel at 10,000 starts must
   reach 1,000,000 start-periods a second on 2 cores.
2. **JIT compile time**, apart: a fresh process that compiles the kernel into an empty cache, and
   one that finds it in the cache (target below 5 s).
3. **Agreement.** The ``K`` starts are taken to where they go on the kernel (the rule of
   ``piezo_fmu.solver.batch.attractors.settle``), and the FMU is marched from each until it shows which of
   those attractors it reaches (``piezo_fmu_harness.starts.destination``): ``agree`` is true when no
   FMU label differs from the kernel's while their trajectories were together.
4. On a machine with an NVIDIA GPU and numba-cuda: the kernel on the GPU at 10,000 and 1,000,000
   starts, and how far its sections end from the CPU's.
5. With ``--studies``: the studies that march many starts, through the command line, timed: the
   201 x 201 basin map at 1.2 sqrt(K/M), the default bifurcation diagram and the default fractions.

Prints one JSON object. The load average before the run is part of it: other programs on the cores
slow every figure; the CPU seconds of each march are given beside the wall time. Each kernel figure
is the median of 5 marches (the best beside it); the FMU's is one march.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import subprocess

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))  # the packages, when not installed

from piezo_fmu import Parameters  # noqa: E402
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, SettleSettings, describe, device_error, settle  # noqa: E402
from piezo_fmu_harness import cli  # noqa: E402
from piezo_fmu_harness.fmu import FmuModel, Instance, default_fmu_path, discard  # noqa: E402
from piezo_fmu_harness.starts.destination import fmu_label  # noqa: E402
# the starts, the drive and the damper of both benchmarks, and the GPU's measures, written once in bench_gpu.py
from bench_gpu import RATIO, VALUES, W_N, Y, starts, with_transfers  # noqa: E402
from bench_gpu import agreement as gpu_agreement  # noqa: E402
from piezo_fmu_harness.periodic.drive import HarmonicDrive  # noqa: E402



#: Start-periods each throughput figure marches (the periods are this over the starts, at least 2).
WORK = 200_000
SIZES = (1, 100, 10_000, 100_000)


#: Times each kernel figure is measured (the median is reported, and the best beside it): one
#: march of 200,000 start-periods takes under a second, and a shared machine's figures scatter by
#: a third from one run to the next.
REPEATS = 5


def batch_rate(states: np.ndarray, drive: HarmonicHold, device: str = "cpu", keep: list | None = None,
               periods: int | None = None) -> dict:
    if periods is None:
        periods = max(2, WORK // len(states))
    runs = []
    for repeat in range(REPEATS):
        ens = Ensemble(Parameters(**VALUES), drive, states, device=device)
        ens.advance(1)  # first touch: imports, the compiled code
        begin, cpu = time.perf_counter(), time.process_time()
        record = ens.advance(periods)
        runs.append((time.perf_counter() - begin, time.process_time() - cpu))
        if keep is not None and repeat == 0:
            keep.append(record)
    wall, cpu = (float(np.median([run[k] for run in runs])) for k in (0, 1))
    work = len(states) * periods
    return {"device": device, "starts": len(states), "periods": periods, "repeats": len(runs), "wall_s": wall,
            "cpu_s": cpu, "start_periods_per_s": work / wall,
            "best_start_periods_per_s": work / min(r[0] for r in runs), "start_periods_per_cpu_s": work / cpu}


def compile_times() -> dict:
    """Seconds a fresh process takes to march one start, with an empty kernel cache (it compiles)
    and then with that cache (it loads)."""
    code = ("import time; t = time.perf_counter()\n"
            "from piezo_fmu import Parameters\n"
            "from piezo_fmu.solver.batch import Ensemble, HarmonicHold\n"
            "e = Ensemble(Parameters(), HarmonicHold(38.0, 1e-3), [(0.0, 0.0, 0.0, 0.0)])\n"
            "e.advance(1); e.separate([[1e-9, 0, 0, 0]], [[1, 1, 1, 1]], [1e-9], 1)\n"
            "print(time.perf_counter() - t)\n")
    times = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(HERE.parent / "src"))
        for name in ("first_call_s", "cache_warm_s"):
            result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
            times[name] = float(result.stdout.split()[-1])
    return times


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
    chaotic transient: ``piezo_fmu_harness.starts.destination``) counts as parted, not as agreeing."""
    from piezo_fmu.solver.batch import tracks
    from piezo_fmu_harness.starts.attractors import merge

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
                              + ["--no-progress"])
            timed[name] = {"wall_s": time.perf_counter() - begin, "exit_status": status,
                           "summary": json.loads((Path(out) / "summary.json").read_text()) if status == 0 else None}
            summary = timed[name]["summary"] or {}
            # the study's own figures: the marching, the FMU's checks, and in all
            timed[name]["marching_s"] = summary.get("marching_s")
            timed[name]["checking_s"] = summary.get("checking_s")
            timed[name]["summary_wall_s"] = summary.get("wall_s")
            timed[name]["fmu_checks"] = {k: v for k, v in summary.get("fmu_checks", {}).items()
                                         if k in ("checked", "agree", "parted", "disagree")}
            timed[name].pop("summary")
    return timed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu-starts", type=int, default=8)
    parser.add_argument("--fmu-periods", type=int, default=20)
    parser.add_argument("--studies", action="store_true")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    omega = RATIO * W_N
    drive = HarmonicHold(omega, Y)
    states = starts(max(SIZES), omega)
    model = FmuModel(default_fmu_path())
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        fmu = fmu_rate(instance, states[:args.fmu_starts], omega, args.fmu_periods)
        kernel = {n: batch_rate(states[:n], drive) for n in SIZES}
        rate = lambda run: run["start_periods_per_s"]  # noqa: E731
        report = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average_before": load,
                  "fmu": fmu, "kernel_cpu": list(kernel.values()),
                  "speedup": rate(kernel[10_000]) / rate(fmu), "single": rate(kernel[1]) / rate(fmu),
                  "jit": compile_times()}
        report.update(agreement(instance, states[:args.fmu_starts], omega))
        if device_error("gpu") is None:  # bench_gpu.py's measures
            report["kernel_gpu"] = [with_transfers("gpu", states[:10_000], drive, 20),
                                    with_transfers("gpu", starts(1_000_000, omega), drive, 10)]
            report["gpu_against_cpu"] = gpu_agreement(states[:10_000], drive, 20)
        else:
            report["kernel_gpu"] = None
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
