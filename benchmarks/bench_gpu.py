"""The compiled kernel on an NVIDIA GPU beside the same kernel on every CPU core of that machine
in one run, with nothing but numpy, scipy, numba and numba-cuda:

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
   loops the CPU runs (``flat_over_nested``, see ``kernel/flat.py``); the CPU's kernel on every core at the sizes up to
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
   (``kernel.gpu.REGISTERS`` is the one measured best).

5. With ``--orderings 1,20,100``: at the largest size, the launch alone from the starts marched
   that many periods, the trajectories in their own order and sorted by their last period (onsets,
   side, ``p``), each order's sections put back and compared with the first's, bit for bit: how
   much of the GPU's time is warps whose threads do unlike work.
6. With ``--march 600``: at the largest size, the launch alone along a march of that many periods
   (``--march-block`` a launch, unobserved as ``settle`` marches), launch by launch, as the
   transients die out: in its own order, and sorted before each launch (on the host, outside the
   clock, its time given apart), the final states compared bit for bit.
7. With ``--settle 100000``: ``settle``, the studies' march (resolved starts leave the ensemble
   after each block), of that many starts at ``--settle-ratio`` (1.25, where the chaotic
   transients are long) to where each goes, on the GPU, and of the first ``--settle-cpu`` on every
   CPU core: the rate a study gets, and how many of the starts both marched went to the same place.

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
from piezo_fmu.solver.batch.model import BatchModel  # noqa: E402

W_N = math.sqrt(1000.0)
RATIO, Y = 1.2, 1e-3
#: The damper as the studies run it: the circuit one-way at the load near the optimum.
VALUES = {"voltage_model": 1, "R_load": 3.59e6}
#: Marches each throughput figure is the median of.
REPEATS = 3
#: A start whose twin, nudged by a bit every period, stays this close (m) is one no chaotic transient
#: parts.
QUIET = 1e-10
#: The target on an H100, start-periods a second at a million starts.
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


def tables_for(drive) -> "kernel.Tables":
    """The benchmark's damper and ``drive`` packed for the kernel."""
    return kernel.Tables(BatchModel.of(Parameters(**VALUES)), [drive])


def whole_state(states: np.ndarray) -> np.ndarray:
    """The kernel's state (7, n) of free starts ``states`` ((n, 4)), the voltages zero."""
    state = np.zeros((7, len(states)))
    state[:4] = states.T
    return state


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


def resident(states: np.ndarray, drive, periods: int, nested: bool = False, target=None, keep: bool = False):
    """Start-periods a second of the GPU launch alone (the flat loop, the GPU's, or with ``nested``
    the nested loops) compiled by ``target`` (the kernel's GPU target when None): the arrays
    on the GPU before the clock starts, the launch timed to the device's synchronisation, after one
    untimed launch that compiles it. With ``keep``, also the sections of the last march."""
    return resident_state(whole_state(states), np.zeros(len(states), bool), drive, periods, nested, target, keep)


def resident_state(state: np.ndarray, failed: np.ndarray, drive, periods: int, nested: bool = False, target=None,
                   keep: bool = False):
    """:func:`resident` from a whole state ((7, n): ``p, p', q, q'``, side, voltages) and its
    ``failed`` flags."""
    from numba import cuda

    tables = tables_for(drive)
    n = state.shape[1]
    host = (True, np.ascontiguousarray(state), failed.copy(), np.zeros(n, np.int64)) + tables.arguments() + (
        np.empty((periods, n, 4)), np.empty((periods, n)), np.empty((periods, n), np.int64),
        np.empty((periods, n)), np.empty((periods, n)))
    from piezo_fmu.solver.batch.kernel import gpu

    compiled = (target or kernel.target("gpu"))(gpu.march if nested else gpu.march_flat)
    launch = compiled[(n + gpu.THREADS - 1) // gpu.THREADS, gpu.THREADS]
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


def orderings(states: np.ndarray, drive, periods: int, transients: list) -> list:
    """The launch alone (as :func:`resident`) from the starts marched ``transients`` periods, with
    the trajectories in their own order and sorted by what their last period did: the same work, in
    warps of threads whose work is alike (a warp executes the union of its threads' branches). Each
    order's sections, put back in the starts' order, must be the first order's bit for bit: a
    trajectory's march does not depend on its neighbours."""
    tables = tables_for(drive)
    n = len(states)
    state, failed, groups = whole_state(states), np.zeros(n, bool), np.zeros(n, np.int64)
    rows, marched = [], 0
    for transient in transients:
        while marched < transient:  # in blocks, whose sections fit in memory at any size
            block = min(transient - marched, 20)
            last = kernel.march("gpu", tables, state, failed, groups, block, observe=False)
            marched += block
        impacts, sides, p = last["impacts"][-1], last["sides"][-1], last["sections"][-1, :, 0]
        orders = {"as_started": np.arange(n), "impacts": np.argsort(impacts, kind="stable"),
                  "impacts_side_p": np.lexsort((p, sides, impacts)), "p": np.argsort(p, kind="stable")}
        moved = int((orders["impacts_side_p"] != np.arange(n)).sum())
        counts = dict(zip(*np.unique(impacts, return_counts=True)))
        row = {"after_periods": transient, "moved_by_impacts_side_p": moved,
               "impacts_last_period": {str(k): int(c) for k, c in counts.items()}}
        first = None
        for key, order in orders.items():
            timing, sections = resident_state(state[:, order], failed[order], drive, periods, keep=True)
            back = np.empty_like(sections)
            back[:, order] = sections
            first = back if first is None else first
            row[key] = {**timing, "same_bits_as_started": bool(np.array_equal(back, first, equal_nan=True))}
            row[key]["over_as_started"] = timing["start_periods_per_s"] / row["as_started"]["start_periods_per_s"]
        rows.append(row)
    return rows


def long_march(states: np.ndarray, drive, total: int, block: int, sort: bool) -> dict:
    """The launch alone (the arrays staying on the GPU, as in :func:`resident`) along a march of
    ``total`` periods from the starts, ``block`` periods a launch, unobserved (as ``settle``
    marches): start-periods a second of each launch, as the transients die out, and of the whole.
    With ``sort``, the trajectories are put in order of their last period (onsets, side, ``p``)
    before each launch, on the host, outside the clock (its time is given apart); their final states,
    put back in the starts' order, are returned for the bits to be compared."""
    from numba import cuda

    tables = tables_for(drive)
    n = len(states)
    state = whole_state(states)
    failed, ids = np.zeros(n, bool), np.arange(n)
    device = [cuda.to_device(a) for a in (state, failed, np.zeros(n, np.int64)) + tables.arguments()]
    outputs = [cuda.device_array(shape, dtype) for shape, dtype in (((block, n, 4), float), ((block, n), float),
                                                                     ((block, n), np.int64), ((block, n), float),
                                                                     ((block, n), float))]
    from piezo_fmu.solver.batch.kernel import gpu

    launch = kernel.target("gpu")(gpu.march_flat)[(n + gpu.THREADS - 1) // gpu.THREADS, gpu.THREADS]
    rates, times, sorting = [], [], 0.0
    for launches_left in range(total // block - 1, -1, -1):
        cuda.synchronize()
        begin = time.perf_counter()
        launch(False, *device, *outputs)
        cuda.synchronize()
        times.append(time.perf_counter() - begin)
        rates.append(round(n * block / times[-1] / 1e6, 1))
        if sort and launches_left:
            begin = time.perf_counter()
            impacts, sides = outputs[2][block - 1].copy_to_host(), outputs[1][block - 1].copy_to_host()
            p = outputs[0][block - 1].copy_to_host()[:, 0]
            order = np.lexsort((p, sides, impacts))
            ids = ids[order]
            state, failed = device[0].copy_to_host()[:, order], device[1].copy_to_host()[order]
            device[0], device[1] = cuda.to_device(np.ascontiguousarray(state)), cuda.to_device(failed)
            sorting += time.perf_counter() - begin
    final = np.empty((7, n))
    final[:, ids] = device[0].copy_to_host()
    row = {"starts": n, "periods": block * len(times), "block": block, "sorted": sort,
           "millions_a_second_each_block": rates, "wall_s": sum(times),
           "start_periods_per_s": n * block * len(times) / sum(times)}
    if sort:
        row["sorting_on_the_host_s"] = sorting
        row["moved"] = int((ids != np.arange(n)).sum())
    return row, final


def settled(states: np.ndarray, ratio: float, budget: int, cpu_starts: int) -> dict:
    """``settle`` (the studies' march: every start to where it goes, resolved starts taken out after
    each block, Newton on the orbits, the undecided measured) at ``ratio`` sqrt(K/M) with a budget of
    ``budget`` periods: all ``states`` on the GPU, the first ``cpu_starts`` of them on every CPU
    core. Wall time, start-periods marched and their rate, the verdicts' counts, and on the starts
    both marched, how many went to the same place (their final sections within 1e-7 m, the same
    side): a chaotic transient parted by the last bit may end on another orbit."""
    from piezo_fmu.solver.batch import SettleSettings, settle

    drive = HarmonicHold(ratio * W_N, Y)
    rows, finals = {}, {}
    # the bookkeeping's compiled code (the CPU's on either device), compiled outside the clock
    settle(Parameters(**VALUES), drive, states[:64], settings=SettleSettings(max_cycles=40), device="cpu")
    for device, count in (("gpu", len(states)), ("cpu", cpu_starts)):
        begin = time.perf_counter()
        result = settle(Parameters(**VALUES), drive, states[:count], settings=SettleSettings(max_cycles=budget),
                        device=device)
        wall = time.perf_counter() - begin
        labels = np.asarray(result.labels)
        rows[device] = {"starts": count, "wall_s": wall, "start_periods": int(result.cycles),
                        "start_periods_per_s": result.cycles / wall, "attractors": len(result.attractors),
                        "undecided": int((labels == -1).sum()), "failed": int((labels == -2).sum()),
                        "median_periods": float(np.median(result.periods)),
                        "longest_periods": int(np.max(result.periods))}
        finals[device] = (np.asarray(result.final)[:cpu_starts], np.asarray(result.final_sides)[:cpu_starts])
    scale = np.array([1.0, 1.0 / drive.omega, 1.0, 1.0 / drive.omega])
    gap = (np.abs(finals["gpu"][0] - finals["cpu"][0]) * scale).max(axis=1)
    same = (gap <= 1e-7) & (finals["gpu"][1] == finals["cpu"][1])
    return {"ratio": ratio, "budget": budget, **rows, "compared": cpu_starts, "same_destination": int(same.sum()),
            "gpu_over_cpu": rows["gpu"]["start_periods_per_s"] / rows["cpu"]["start_periods_per_s"]}


def register_caps(states: np.ndarray, drive, periods: int, caps: list) -> list:
    """The GPU's flat march compiled for each cap of registers a thread (0: the compiler's choice):
    its registers and local memory a thread, start-periods a second (the launch alone), and whether
    its sections are the first cap's, bit for bit (a cap moves spills, not arithmetic)."""
    rows, first = [], None
    for cap in caps:
        begin = time.perf_counter()
        from piezo_fmu.solver.batch.kernel import gpu

        target = gpu.build(cap or None)
        row, sections = resident(states, drive, periods, target=target, keep=True)
        compiled = target(gpu.march_flat)
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
    tables = tables_for(drive)
    n = len(states)
    state, failed, groups = whole_state(states), np.zeros(n, bool), np.zeros(n, np.int64)
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
    parser.add_argument("--orderings", default="", help="periods of transient after which the launch is timed "
                        "with the trajectories sorted by their last period, at the largest size, comma-separated; "
                        "none by default")
    parser.add_argument("--march", type=int, default=0, help="periods of a long march at the largest size, "
                        "timed launch by launch, in its own order and sorted; none by default")
    parser.add_argument("--march-block", type=int, default=20, help="periods a launch of the long march")
    parser.add_argument("--settle", type=int, default=0, help="starts settled as a study does, on the GPU "
                        "(and --settle-cpu of them on the CPU); none by default")
    parser.add_argument("--settle-cpu", type=int, default=10_000)
    parser.add_argument("--settle-ratio", type=float, default=1.25, help="its frequency over sqrt(K/M)")
    parser.add_argument("--settle-budget", type=int, default=6000, help="its budget of periods a start")
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
               "gpu_resident_nested": resident(states[:n], drive, args.periods, nested=True)}
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
    if args.orderings:
        transients = [int(t) for t in args.orderings.split(",")]
        report["orderings"] = orderings(states[:sizes[-1]], drive, args.periods, transients)
    if args.march:
        block = min(args.march_block, args.march)
        plain, plain_final = long_march(states[:sizes[-1]], drive, args.march, block, sort=False)
        ordered, ordered_final = long_march(states[:sizes[-1]], drive, args.march, block, sort=True)
        ordered["same_bits_as_unsorted"] = bool(np.array_equal(plain_final, ordered_final, equal_nan=True))
        ordered["over_unsorted"] = ordered["start_periods_per_s"] / plain["start_periods_per_s"]
        report["long_march"] = [plain, ordered]
    if args.settle:
        many = starts(args.settle, args.settle_ratio * W_N)
        report["settle"] = settled(many, args.settle_ratio, args.settle_budget, min(args.settle_cpu, args.settle))
    largest = rows[-1]["gpu_resident"]["start_periods_per_s"]
    report["target"] = {"start_periods_per_s": TARGET, "at_starts": 1_000_000, "largest_size": sizes[-1],
                        "resident_at_largest": largest, "met": sizes[-1] >= 1_000_000 and largest >= TARGET}
    report["agreement"] = agreement(states[:args.agree], drive, args.agree_periods)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
