"""The random-excitation study, timed: the whole command against its target, and its parts side by
side in one run.

    python benchmarks/bench_random.py [--realizations 1000] [--duration 300] [--jobs 2] [--gpu 10000]

1. **The study** (``piezo-fmu random``, the nominal damper under Kanai-Tajimi firm soil at the default
   level, with and without the damper, ``--confirm 0``): its wall time against the target (60 s for
   1,000 realizations of 300 s on 2 cores), and the largest resident memory of the command and of
   its workers (target below 2 GB).
2. **Its parts**, on one core, for 50 realizations of 60 s: generating the inputs
   (``piezo_fmu_harness.excitation``), marching them without the damper (free flight only) and with
   it (impacts), in realization-steps a second, and the ratios of the three.
3. With ``--gpu N`` on a machine with an NVIDIA GPU and numba-cuda: one level of ``N`` realizations
   marched on the GPU beside the CPU (every core), the same inputs, realization-steps a second.

Prints one JSON object; the load average before the run is part of it (other programs on the cores
slow every figure).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))

#: The study's target on 2 cores (s) and memory (MB).
TARGET_S, TARGET_MB = 60.0, 2000.0


def study(realizations: int, duration: float, jobs: int) -> dict:
    """``piezo-fmu random`` in a process of its own: its wall time and its largest memory."""
    with tempfile.TemporaryDirectory() as folder:
        command = [sys.executable, "-m", "piezo_fmu_harness", "random", "--realizations", str(realizations),
                   "--duration", str(duration), "--confirm", "0", "--jobs", str(jobs), "--no-progress",
                   "--out", str(Path(folder) / "out")]
        begin = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(HERE.parent / "src")})
        wall = time.perf_counter() - begin
        if done.returncode:
            raise SystemExit(f"bench_random: the study failed:\n{done.stderr[-3000:]}")
        summary = json.loads((Path(folder) / "out" / "summary.json").read_text())
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    (level,) = summary["levels"]
    return {"realizations": realizations, "window_s": duration, "warmup_s": summary["warmup_s"], "jobs": jobs,
            "wall_s": wall, "marching_s": summary["marching_s"], "largest_process_mb": children,
            "target_s": TARGET_S * realizations / 1000 * duration / 300, "met": wall <= TARGET_S * realizations / 1000
            * duration / 300 and children <= TARGET_MB, "ratio": level["ratio"], "ratio_ci": level["ratio_ci"]}


def parts(realizations: int = 50, duration: float = 60.0) -> dict:
    """Generation, the march without and with the damper, on one core (see the module's text)."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from piezo_fmu import Parameters
    from piezo_fmu.solver.batch.input_ensemble import InputEnsemble
    from piezo_fmu_harness.excitation import Excitation, KanaiTajimi

    step = 0.004
    steps = int(duration / step)
    excitation = Excitation(KanaiTajimi.soil("firm", 0.01), step=step)
    begin = time.perf_counter()
    y, v = excitation.chunk(range(realizations)).take(steps)
    generated = time.perf_counter() - begin
    nodes, slopes = np.ascontiguousarray(y.T), np.ascontiguousarray(v.T)
    rates = {"generation": realizations * steps / generated}
    for case, gap in (("without", {"d": 1000.0}), ("with", {})):
        params = Parameters(voltage_model=2, R_load=3.59e6, **gap)
        InputEnsemble(params, step, np.zeros((1, 4))).advance(nodes[:1, :11], slopes[:1, :10])  # compiled or loaded
        ensemble = InputEnsemble(params, step, np.zeros((realizations, 4)))
        begin = time.perf_counter()
        ensemble.advance(nodes, slopes)
        rates[f"march_{case}"] = realizations * steps / (time.perf_counter() - begin)
        rates[f"impacts_per_second_{case}"] = float(ensemble.counts.mean() / duration)
    return {"realizations": realizations, "window_s": duration, "realization_steps_per_s": rates,
            "march_with_over_without": rates["march_with"] / rates["march_without"],
            "generation_over_march_with": rates["generation"] / rates["march_with"]}


def gpu(realizations: int, duration: float = 60.0) -> dict:
    """One level of ``realizations`` on the GPU beside every CPU core."""
    from piezo_fmu import Parameters
    from piezo_fmu.solver.batch import device_error
    from piezo_fmu.solver.batch.input_ensemble import InputEnsemble
    from piezo_fmu_harness.excitation import Excitation, KanaiTajimi

    if device_error("gpu"):
        return {"skipped": device_error("gpu")}
    step = 0.004
    steps = int(duration / step)
    y, v = Excitation(KanaiTajimi.soil("firm", 0.01), step=step).chunk(range(realizations)).take(steps)
    nodes, slopes = np.ascontiguousarray(y.T), np.ascontiguousarray(v.T)
    rates, positions = {}, {}
    for device in ("gpu", "cpu"):
        params = Parameters(voltage_model=2, R_load=3.59e6)
        InputEnsemble(params, step, np.zeros((1, 4)), device=device).advance(nodes[:1, :11], slopes[:1, :10])
        ensemble = InputEnsemble(params, step, np.zeros((realizations, 4)), device=device)
        begin = time.perf_counter()
        positions[device] = ensemble.advance(nodes, slopes)
        rates[device] = realizations * steps / (time.perf_counter() - begin)
    return {"realizations": realizations, "window_s": duration, "realization_steps_per_s": rates,
            "gpu_over_cpu": rates["gpu"] / rates["cpu"],
            "first_second_max_difference_m": float(np.abs(positions["gpu"][:, :250] - positions["cpu"][:, :250]).max())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realizations", type=int, default=1000)
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--gpu", type=int, default=0, metavar="N", help="realizations on the GPU (0: none)")
    parser.add_argument("--no-study", action="store_true", help="the parts only")
    args = parser.parse_args(argv)
    report = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average_before": os.getloadavg()[0]}
    if not args.no_study:
        report["study"] = study(args.realizations, args.duration, args.jobs)
    report["parts_one_core"] = parts()
    if args.gpu:
        report["gpu"] = gpu(args.gpu)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
