"""The compiled kernel on an NVIDIA GPU beside the same kernel on every CPU core of that machine
(issue 32), in one run, with nothing but numpy, scipy, numba and numba-cuda:

    PYTHONPATH=src python3 benchmarks/bench_gpu.py [--sizes 10000,100000,1000000] [--periods 10]

It reads the source tree (``src``) and no FMU, fmpy or other dependency of the harness, so that it
runs as it is on a GPU machine whose Python image carries numba-cuda and can install nothing (the
device machines lent to some sessions: one call, within minutes). ``bench_batch.py`` measures the
same GPU figures beside the FMU's where the whole harness is installed.

Random starts at 1.2 sqrt(K/M), those of ``bench_batch.py`` (the nominal damper, ``Y`` = 1 mm,
64 hold steps a period):

1. **Compile**: the first GPU march (numba's CUDA compilation and the launch), in seconds.
2. **Throughput** at each size: start-periods a second on the GPU, the median of a few marches:
   ``with_transfers`` as a study gets it (``Ensemble.advance``: the states copied in and the
   sections copied out every call), and ``resident`` (the launch alone on arrays already on the
   GPU, timed to the device's synchronisation), for the GPU's flat loop and, beside it, the nested
   loops the CPU runs (``flat_over_nested``, see ``kernel_flow.py``); the CPU's kernel on every core at the sizes up to
   100,000 beside it (``gpu_over_cpu``). Target: 100 million start-periods a second at a million
   starts on an H100.
3. **Agreement**: 10,000 starts marched 20 periods on both. A chaotic transient parts two
   trajectories that differ in the last bit (``cos`` and ``exp`` are the C library's on the CPU and
   CUDA's on the GPU, and the GPU fuses multiply-adds), so the sections are compared over all
   starts, where the contact onsets stayed the same in every period, and where a twin nudged by one
   bit at every period stays within 1e-10 m on the CPU alone (no chaotic transient parts them
   there). Target: within 1e-9 m there.

4. With ``--registers 0,128,96,64``: the flat march compiled for each cap of registers a thread
   (0: the compiler's choice) at the largest size, with the same bits or not
   (``kernel.GPU_REGISTERS`` is the one measured best).

Prints one JSON object. With ``NUMBA_ENABLE_CUDASIM=1`` it runs on numba's CUDA simulator
(slowly: small sizes only), which checks the script, not the GPU.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "src"))

from piezo_fmu import Parameters  # noqa: E402
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, device_error  # noqa: E402
from piezo_fmu.solver.batch import kernel  # noqa: E402
from piezo_fmu.solver.batch.phases import BatchModel  # noqa: E402

W_N = math.sqrt(1000.0)
RATIO, Y = 1.2, 1e-3
#: The damper as the studies run it: the circuit one-way at the load near the optimum.
VALUES = {"voltage_model": 1, "R_load": 3.59e6}
#: Marches each throughput figure is the median of.
REPEATS = 3
#: A start whose twin, nudged by a bit every period, stays this close (m) is one no chaotic transient
#: parts.
QUIET = 1e-10
#: The target of issue 32 on an H100, start-periods a second at a million starts.
TARGET = 100e6


def starts(count: int, omega: float) -> np.ndarray:
    """Random starts (seeded): ``p0`` and ``p0'/w`` within two linear amplitudes, the impact mass at
    rest in the middle. ``bench_batch.py`` marches the same."""
    M, K, C = 1.0, 1000.0, 0.1  # the nominal main body (``linear_transmissibility`` of the harness)
    transmissibility = np.sqrt((K**2 + (C * omega) ** 2) / ((K - M * omega**2) ** 2 + (C * omega) ** 2))
    span = 2.0 * Y * float(transmissibility)
    rng = np.random.default_rng(2026)
    p0 = rng.uniform(-span, span, count)
    return np.stack([p0, rng.uniform(-span * omega, span * omega, count), p0, np.zeros(count)], axis=1)


def with_transfers(device: str, states: np.ndarray, drive, periods: int) -> dict:
    """Start-periods a second of ``Ensemble.advance`` (a fresh ensemble each march, after a
    first period that loads the compiled code)."""
    times, cpu = [], []
    for _ in range(REPEATS):
        ens = Ensemble(Parameters(**VALUES), drive, states, device=device)
        ens.advance(1)
        begin, clock = time.perf_counter(), time.process_time()
        ens.advance(periods)
        times.append(time.perf_counter() - begin)
        cpu.append(time.process_time() - clock)
    work = len(states) * periods
    return {"device": device, "starts": len(states), "periods": periods, "wall_s": float(np.median(times)),
            "start_periods_per_s": work / float(np.median(times)), "best_start_periods_per_s": work / min(times),
            "cpu_s": float(np.median(cpu))}


def resident(states: np.ndarray, drive, periods: int, name: str = "march_flat", namespace: dict | None = None,
             keep: bool = False):
    """Start-periods a second of the GPU launch ``name`` alone (``march_flat``, the GPU's, or
    ``march``, the nested loops) from ``namespace`` (the kernel's GPU target when None): the arrays
    on the GPU before the clock starts, the launch timed to the device's synchronisation, after one
    untimed launch that compiles it. With ``keep``, also the sections of the last march."""
    from numba import cuda

    tables = kernel.Tables(BatchModel.of(Parameters(**VALUES)), [drive])
    n = len(states)
    state = np.zeros((7, n))
    state[:4] = states.T
    host = (True, state, np.zeros(n, bool), np.zeros(n, np.int64)) + tables.arguments() + (
        np.empty((periods, n, 4)), np.empty((periods, n)), np.empty((periods, n), np.int64),
        np.empty((periods, n)), np.empty((periods, n)))
    compiled = (namespace or kernel.target("gpu"))[name]
    launch = compiled[(n + kernel.GPU_THREADS - 1) // kernel.GPU_THREADS, kernel.GPU_THREADS]
    times = []
    for k in range(REPEATS + 1):
        args = [cuda.to_device(a) if isinstance(a, np.ndarray) else a for a in host]  # the same start each time
        cuda.synchronize()
        begin = time.perf_counter()
        launch(*args)
        cuda.synchronize()
        if k:
            times.append(time.perf_counter() - begin)
    work = n * periods
    row = {"starts": n, "periods": periods, "wall_s": float(np.median(times)),
           "start_periods_per_s": work / float(np.median(times)), "best_start_periods_per_s": work / min(times)}
    return (row, args[6].copy_to_host()) if keep else row


def register_caps(states: np.ndarray, drive, periods: int, caps: list) -> list:
    """The GPU's flat march compiled for each cap of registers a thread (0: the compiler's choice):
    its registers and local memory a thread, start-periods a second (the launch alone), and whether
    its sections are the first cap's, bit for bit (a cap moves spills, not arithmetic)."""
    rows, first = [], None
    for cap in caps:
        begin = time.perf_counter()
        namespace = kernel._gpu(cap or None)
        row, sections = resident(states, drive, periods, namespace=namespace, keep=True)
        compiled = namespace["march_flat"]
        row = {"registers_cap": cap or None, "with_compile_s": time.perf_counter() - begin, **row}
        for key, method in (("registers", "get_regs_per_thread"), ("local_bytes", "get_local_mem_per_thread")):
            if hasattr(compiled, method):  # not on numba's simulator
                value = getattr(compiled, method)()
                row[key] = next(iter(value.values())) if isinstance(value, dict) else value
        first = sections if first is None else first
        row["same_bits_as_first"] = bool(np.array_equal(sections, first, equal_nan=True))
        rows.append(row)
    return rows


def nudged_twin(states: np.ndarray, drive, periods: int) -> dict:
    """The starts marched on the CPU with a last-bit difference put in at every period: ``p, p',
    q, q'`` moved to the next float at each section. Sections and onsets as ``Ensemble.advance``
    gives them."""
    tables = kernel.Tables(BatchModel.of(Parameters(**VALUES)), [drive])
    n = len(states)
    state, failed, groups = np.zeros((7, n)), np.zeros(n, bool), np.zeros(n, np.int64)
    state[:4] = states.T
    rows = []
    for _ in range(periods):
        state[:4] = np.nextafter(state[:4], np.inf)
        rows.append(kernel.march("cpu", tables, state, failed, groups, 1, observe=False))
    return {k: np.concatenate([row[k] for row in rows]) for k in ("sections", "impacts", "sides")}


def agreement(states: np.ndarray, drive, periods: int) -> dict:
    """The same starts marched on both: how far the GPU's sections are from the CPU's, everywhere
    and where no chaotic transient parts them. That is judged on the CPU alone, by a twin of each
    start with a last-bit difference put in at every period (:func:`nudged_twin`): where the twin
    stays within :data:`QUIET` of the start's march, the motion does not amplify last-bit
    differences, and the GPU (whose ``cos``, ``exp`` and fused multiply-adds differ from the CPU's in
    the last bit, at every step) must agree within 1e-9 m."""
    gpu, cpu = (Ensemble(Parameters(**VALUES), drive, states, device=d).advance(periods) for d in ("gpu", "cpu"))
    twin = nudged_twin(states, drive, periods)
    scale = np.array([1.0, 1.0 / drive.omega, 1.0, 1.0 / drive.omega])  # m, and m/s as m

    def apart(a, b):
        gap = (np.abs(a["sections"] - b["sections"]) * scale).max(axis=(0, 2))
        same = (a["impacts"] == b["impacts"]).all(axis=0) & (a["sides"] == b["sides"]).all(axis=0)
        return gap, same

    gap, same = apart(gpu, cpu)
    twin_gap, twin_same = apart(twin, cpu)
    quiet = same & twin_same & (twin_gap <= QUIET)
    kept, calm = gap[same], gap[quiet]
    return {"starts": len(states), "periods": periods, "impacting": int((cpu["impacts"].sum(axis=0) > 0).sum()),
            "same_onsets_every_period": int(same.sum()),
            "max_difference_same_onsets_m": float(kept.max()) if kept.size else None,
            "within_1e-9_m_same_onsets": int((kept <= 1e-9).sum()),
            "max_difference_all_m": float(gap.max()), "median_difference_all_m": float(np.median(gap)),
            "cpu_twin_beyond_1e-9_m": int((twin_gap > 1e-9).sum()), "gpu_beyond_1e-9_m": int((gap > 1e-9).sum()),
            "not_parted": int(quiet.sum()), "max_difference_not_parted_m": float(calm.max()) if calm.size else None,
            "within_1e-9_m_not_parted": int((calm <= 1e-9).sum())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="10000,100000,1000000", help="starts, comma-separated")
    parser.add_argument("--periods", type=int, default=10, help="periods each throughput march")
    parser.add_argument("--agree", type=int, default=10_000, help="starts compared with the CPU")
    parser.add_argument("--agree-periods", type=int, default=20)
    parser.add_argument("--cpu-up-to", type=int, default=100_000, help="largest size also marched on the CPU")
    parser.add_argument("--registers", default="", help="register caps a thread to compare at the largest size, "
                        "comma-separated (0: the compiler's choice); none by default")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    import numba

    report = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average_before": os.getloadavg()[0],
              "numba": numba.__version__, "simulator": os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"}
    error = device_error("gpu")
    if error is not None:
        report["gpu"] = error
        print(json.dumps(report, indent=2))
        return 1
    from numba import cuda

    name = getattr(cuda.get_current_device(), "name", "numba's CUDA simulator")
    report["gpu"] = name.decode() if isinstance(name, bytes) else str(name)
    omega = RATIO * W_N
    drive = HarmonicHold(omega, Y)
    states = starts(max(sizes + [args.agree]), omega)
    begin = time.perf_counter()
    Ensemble(Parameters(**VALUES), drive, states[:1], device="gpu").advance(1)
    report["first_gpu_march_s"] = time.perf_counter() - begin
    Ensemble(Parameters(**VALUES), drive, states[:1], device="cpu").advance(1)
    rows = []
    for n in sizes:
        row = {"starts": n, "gpu_with_transfers": with_transfers("gpu", states[:n], drive, args.periods),
               "gpu_resident": resident(states[:n], drive, args.periods),
               "gpu_resident_nested": resident(states[:n], drive, args.periods, "march")}
        row["flat_over_nested"] = (row["gpu_resident"]["start_periods_per_s"]
                                   / row["gpu_resident_nested"]["start_periods_per_s"])
        if n <= args.cpu_up_to:
            row["cpu_every_core"] = with_transfers("cpu", states[:n], drive, args.periods)
            row["gpu_over_cpu"] = (row["gpu_with_transfers"]["start_periods_per_s"]
                                   / row["cpu_every_core"]["start_periods_per_s"])
        rows.append(row)
    report["throughput"] = rows
    if args.registers:
        caps = [int(c) for c in args.registers.split(",")]
        report["register_caps"] = register_caps(states[:sizes[-1]], drive, args.periods, caps)
    largest = rows[-1]["gpu_resident"]["start_periods_per_s"]
    report["target"] = {"start_periods_per_s": TARGET, "at_starts": 1_000_000, "largest_size": sizes[-1],
                        "resident_at_largest": largest, "met": sizes[-1] >= 1_000_000 and largest >= TARGET}
    report["agreement"] = agreement(states[:args.agree], drive, args.agree_periods)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
