"""Throughput of the sweep engine on the paper's Figs. 4-9 preset set, in one run.

    python benchmarks/bench_sweep.py [--step S] [--jobs N] [--naive-points 20] [--core-points 60]

1. The engine: the full ``figs4-9`` preset set (2 x 31 x 31 = 1922 points, each 0 to 2 s at the
   communication step ``--step``, default the sweep default) on the local process pool over all
   cores, worker start-up included; then the results as ``piezo-fmu sweep`` writes them (NetCDF,
   CSV, zones, Figs. 4-9), timed apart: writing them should take at most 20% of the simulation.
2. The naive loop: ``fmpy.simulate_fmu(fmu_file, ...)`` called afresh per point, one core, the
   same communication step, on ``--naive-points`` points spread over the preset set; its
   points/s is extrapolated to the whole set.
3. The core in-process on one core: ``Simulator(Parameters(**kw)).advance(2.0, 0, 0)`` on
   ``--core-points`` points spread over the set (the benchmark may import the core; the harness
   never does).
4. The step's price: on ``--compare-points`` points, one in-process FMU instance (what a
   worker does) against the naive loop at the chosen step and each of ``--compare-steps``
   (default 0.1 s, 0.01 s and 1e-3 s): the step trades the two ratios against each other.

Every cost is measured twice: wall time, and CPU time (``time.process_time`` of the process that
does the work; each engine worker times its own points). Wall time is what a user waits; CPU
time is what the work costs and does not change when other programs share the cores, so the
ratios are given from both. The targets: >= 5x the naive loop's points/s; within 1.5x the
core's points/s per core; the whole set under 30 s (wall). The design zones found are printed
beside the paper's.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))  # the packages, when not installed

from fmpy import simulate_fmu  # noqa: E402

from piezo_fmu_harness import cli  # noqa: E402
from piezo_fmu_harness.studies.sweep import analysis  # noqa: E402
from piezo_fmu_harness.studies.sweep import command as commands  # noqa: E402
from piezo_fmu_harness.engine import ProcessPool, default_jobs  # noqa: E402
from piezo_fmu_harness.fmu import FmuModel, Instance, default_fmu_path, discard  # noqa: E402
from piezo_fmu_harness.spec import DEFAULT_SWEEP_STEP  # noqa: E402
from piezo_fmu_harness.studies.sweep.run import display, execute, open_sweep, write_results  # noqa: E402

TARGET_NAIVE = 5.0
TARGET_CORE = 1.5
TARGET_SECONDS = 30.0
TARGET_OUTPUTS = 0.2


def spread(items: list, count: int) -> list:
    """``count`` items evenly strided over ``items``."""
    if count >= len(items):
        return list(items)
    stride = len(items) / count
    return [items[int(k * stride)] for k in range(count)]


def per_point(run, subset: list) -> dict:
    """Mean wall and CPU seconds of ``run(t_end, values)`` over ``subset``."""
    wall = cpu = 0.0
    for t_end, values in subset:
        w0, c0 = time.perf_counter(), time.process_time()
        run(t_end, values)
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
    return {"wall_s": wall / len(subset), "cpu_s": cpu / len(subset), "points_timed": len(subset)}


def sweep_and_write(model, runs, sweeps, panels, out: Path, jobs: int) -> dict:
    """Run the sweeps on the process pool, then write their results; time both (wall and CPU)."""
    unzipdir = model.extract()
    begin, begin_cpu = time.perf_counter(), time.process_time()
    execute(runs, ProcessPool(model, unzipdir, jobs), progress=False)
    engine_s, main_cpu_s = time.perf_counter() - begin, time.process_time() - begin_cpu
    discard(unzipdir)
    begin, before = time.perf_counter(), os.times()
    parts: dict = {}
    results = write_results(model, runs, [name for name, _, _ in sweeps], panels, out, jobs=jobs, timings=parts)
    outputs_s, after = time.perf_counter() - begin, os.times()
    # CPU of this process and of the forked figure processes (reaped, so counted in os.times).
    outputs_cpu_s = sum(getattr(after, f) - getattr(before, f)
                        for f in ("user", "system", "children_user", "children_system"))
    return {"engine_s": engine_s, "main_cpu_s": main_cpu_s, "outputs_s": outputs_s, "outputs_cpu_s": outputs_cpu_s,
            "parts": parts, "total_s": engine_s + outputs_s, "results": results}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--step", type=float, default=DEFAULT_SWEEP_STEP, help="communication step, s")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="engine worker processes")
    parser.add_argument("--naive-points", type=int, default=20)
    parser.add_argument("--core-points", type=int, default=60)
    parser.add_argument("--compare-steps", type=float, nargs="*", default=[0.1, 0.01, 1e-3], metavar="S",
                        help="other communication steps to price on a few points (default 0.1 0.01 1e-3)")
    parser.add_argument("--compare-points", type=int, default=20)
    parser.add_argument("--fmu", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=None, help="keep the sweep results here")
    args = parser.parse_args()

    model = FmuModel(args.fmu or default_fmu_path())
    fmu_file = str(model.path)
    load_before = os.getloadavg()
    scratch = None if args.out else Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    out = args.out or scratch / "figs4-9"
    try:
        cli_args = cli._parser().parse_args(["sweep", "--preset", "figs4-9", "--out", str(out),
                                             "--step", repr(args.step)])
        sweeps, panels, _ = commands.sweep_specs(cli_args, model)
        runs = [open_sweep(model, spec, folder, resume=False, force=True) for _, spec, folder in sweeps]
        for run in runs:
            run.begin()
        points = [(run.spec.stop_time, values) for run in runs for _, values in run.todo()]
        stop_time = runs[0].spec.stop_time

        # 1. the engine, worker start-up included, then the results as the command writes them
        timed = sweep_and_write(model, runs, sweeps, panels, out, args.jobs)
        engine_s, results = timed["engine_s"], timed.pop("results")
        records = [r for run in runs for r in run.done.values()]
        worker = {"wall_s": statistics.mean(r["seconds"] for r in records),
                  "cpu_s": statistics.mean(r["cpu_seconds"] for r in records)}

        # 2. the naive loop: a fresh simulate_fmu per point, same communication step
        simulate_fmu(fmu_file, stop_time=1e-3, output_interval=1e-3)  # warm-up: the FMU's first imports
        naive = per_point(lambda t, v: simulate_fmu(fmu_file, start_values=v, stop_time=t, output_interval=args.step),
                          spread(points, args.naive_points))

        # 3. the core in-process, one core
        from piezo_fmu import Parameters, Simulator

        Simulator(Parameters()).advance(0.1, 0.0, 0.0)  # warm-up
        core = per_point(lambda t, v: Simulator(Parameters(**v)).advance(t, 0.0, 0.0),
                         spread(points, args.core_points))

        # 4. the step's price: one FMU instance in-process (a worker's loop) against the naive loop
        compare_dir = model.extract()
        instance = Instance(model, compare_dir)
        compare = spread(points, args.compare_points)
        steps = {}
        for step in [args.step, *args.compare_steps]:
            mine = per_point(lambda t, v: instance.run(v, t, step), compare)
            theirs = per_point(lambda t, v: simulate_fmu(fmu_file, start_values=v, stop_time=t, output_interval=step),
                               compare)
            steps[repr(step)] = {
                "worker_point_cpu_s": mine["cpu_s"], "naive_point_cpu_s": theirs["cpu_s"],
                "worker_over_core": mine["cpu_s"] / core["cpu_s"],
                "naive_over_worker_per_core": theirs["cpu_s"] / mine["cpu_s"],
                "predicted_engine_over_naive": args.jobs * theirs["cpu_s"] / mine["cpu_s"],
                "predicted_set_s": len(points) * mine["cpu_s"] / args.jobs,
            }
        instance.free()
        shutil.rmtree(compare_dir, ignore_errors=True)
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)

    total = len(records)
    engine_pps = total / engine_s
    ratios = {
        "wall": {"engine_over_naive": engine_pps * naive["wall_s"],
                 "engine_cost_over_core": (engine_s / total * args.jobs) / core["wall_s"]},
        "cpu": {"engine_over_naive": args.jobs * naive["cpu_s"] / worker["cpu_s"],
                "engine_cost_over_core": worker["cpu_s"] / core["cpu_s"]},
    }
    report = {
        "case": (f"Figs. 4-9 preset set: {total} points, each 0 to {stop_time:g} s, communication step "
                 f"{args.step:g} s; engine = process pool of {args.jobs} workers; {os.cpu_count()} cores"),
        "load_average_before": [round(x, 2) for x in load_before],
        "engine": {"wall_s": engine_s, "points_per_s": engine_pps, "point_in_worker": worker,
                   "workers_cpu_s": sum(r["cpu_seconds"] for r in records),
                   "rejected_points": sum(r["status"] != "ok" for r in records)},
        "outputs": {**timed, "share_of_simulation": timed["outputs_s"] / engine_s},
        "naive_fmpy_loop": {**naive, "points_per_s": 1 / naive["wall_s"], "extrapolated_set_s": total * naive["wall_s"]},
        "core_in_process": {**core, "points_per_s": 1 / core["wall_s"], "extrapolated_set_one_core_s": total * core["wall_s"]},
        "ratios": ratios,
        "targets": {
            f"engine >= {TARGET_NAIVE:g}x naive (wall)": ratios["wall"]["engine_over_naive"] >= TARGET_NAIVE,
            f"engine >= {TARGET_NAIVE:g}x naive (CPU)": ratios["cpu"]["engine_over_naive"] >= TARGET_NAIVE,
            f"within {TARGET_CORE:g}x the core per core (wall)": ratios["wall"]["engine_cost_over_core"] <= TARGET_CORE,
            f"within {TARGET_CORE:g}x the core per core (CPU)": ratios["cpu"]["engine_cost_over_core"] <= TARGET_CORE,
            f"set under {TARGET_SECONDS:g} s (wall)": engine_s < TARGET_SECONDS,
            f"outputs at most {100 * TARGET_OUTPUTS:g}% of the simulation (wall)":
                timed["outputs_s"] <= TARGET_OUTPUTS * engine_s,
        },
        "steps_compared": {"points_timed": len(compare), "by_step": steps},
        "zones": {name: result["zones"] for name, result in results.items()},
    }
    if args.out is not None:
        (out / "benchmark.json").write_text(json.dumps(report, indent=2) + "\n")

    ms = lambda seconds: f"{1e3 * seconds:6.1f} ms"  # noqa: E731
    print(report["case"])
    print(f"load average before: {report['load_average_before']} (other programs on the cores slow the wall times)")
    print(f"engine      {engine_s:6.2f} s wall for {total} points = {engine_pps:6.1f} points/s; a point in a worker "
          f"{ms(worker['wall_s'])} wall, {ms(worker['cpu_s'])} CPU")
    parts = timed["parts"]
    print(f"outputs     after {engine_s:.2f} s of simulation, {timed['outputs_s']:.2f} s wall = "
          f"{100 * timed['outputs_s'] / engine_s:.0f}% of it (target <= {100 * TARGET_OUTPUTS:g}%), "
          f"{timed['outputs_cpu_s']:.2f} s CPU: datasets {parts['datasets_s']:.2f} s, {parts['figures']} figures in "
          f"{args.jobs} processes {parts['figures_s']:.2f} s, NetCDF, CSV and zones meanwhile {parts['files_s']:.2f} s; "
          f"simulation and outputs {timed['total_s']:.2f} s")
    print(f"naive loop  {ms(naive['wall_s'])} wall, {ms(naive['cpu_s'])} CPU per point = {1 / naive['wall_s']:6.1f} "
          f"points/s ({naive['points_timed']} points timed; the set would take {total * naive['wall_s']:.0f} s)")
    print(f"core        {ms(core['wall_s'])} wall, {ms(core['cpu_s'])} CPU per point = {1 / core['wall_s']:6.1f} "
          f"points/s on one core ({core['points_timed']} points timed; the set: {total * core['wall_s']:.0f} s on one core)")
    for kind in ("wall", "cpu"):
        r = ratios[kind]
        print(f"ratios ({kind:4s}) engine / naive = {r['engine_over_naive']:5.2f} (target >= {TARGET_NAIVE:g}); "
              f"engine per core costs {r['engine_cost_over_core']:4.2f}x the core (target <= {TARGET_CORE:g})")
    print(f"step price  (CPU, {len(compare)} points, one instance; 'predicted' for {args.jobs} workers)")
    for step, row in steps.items():
        print(f"  step {float(step):<7g} worker {ms(row['worker_point_cpu_s'])} ({row['worker_over_core']:.2f}x core), "
              f"naive {ms(row['naive_point_cpu_s'])}: predicted engine / naive {row['predicted_engine_over_naive']:.2f}, "
              f"set {row['predicted_set_s']:.0f} s")
    print("targets     " + "; ".join(f"{name}: {'met' if ok else 'NOT met'}" for name, ok in report["targets"].items()))
    for name, result in results.items():
        print("\n".join(analysis.zone_summary_lines(result["zones"], display(result["dataset"]))))


if __name__ == "__main__":
    main()
