"""The forced response and the optimiser, timed, beside the free-decay sweep, in one run.

    python benchmarks/bench_forced.py [--jobs N] [--out DIR]

1. The default frequency response: 61 frequencies from 0.5 to 2 sqrt(K/M), Y = 1 mm, with and
   without the damper, up and down (244 points, each a stable orbit or a motion that is not
   periodic), on the process pool of ``--jobs`` workers, worker start-up included; then its files
   and figures, timed apart. The forcing cycles simulated are split into the shooting (marching,
   Newton, verification, measures), the stability checks (Floquet multipliers), the search on
   from unstable orbits and the windows of the undecided points: the cost of the stability checks
   against the shooting alone, in the same run.
2. The free-decay sweep of the Figs. 4-9 preset (1922 points of 2 s) on the same pool: the
   points per second of each.
3. One optimisation with the defaults of ``piezo-fmu optimize`` (``--seed 1``: its default when its
   figures were measured): the paper's perfectibility over ``m`` (0.02 to 0.2 kg) and ``d`` (3 to
   10 mm), differential evolution (15 x 2 designs a generation, at most 30 generations) on the
   same pool, then the grid of the same budget and the sensitivity: its evaluations and wall time.
4. The default ``piezo-fmu continuation`` (seeds from 16 frequencies up and down, every orbit with
   impacts followed; target under 60 s on 2 cores): wall time, points, runs of the period map per
   point.
5. The default ``piezo-fmu bifurcation`` (200 frequencies, up and down, on the batch engine; target
   under 30 s) and the default ``piezo-fmu basins --ratio 1.2`` (101 x 101 starts on the
   batch engine; ``bench_batch.py --studies`` times the 201 x 201 map against its 5 minutes): wall time
   and the work a point.

Wall and CPU times (the CPU time of the workers, each timing its own points). The load average
before the run is printed: other programs on the cores slow the wall times.
"""

from __future__ import annotations

import argparse
import contextlib
import io
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

from piezo_fmu_harness import cli  # noqa: E402
from piezo_fmu_harness.periodic.band import frequency_spec  # noqa: E402
from piezo_fmu_harness.studies.forced import chains as fr  # noqa: E402
from piezo_fmu_harness.studies.forced import results as frequency_results  # noqa: E402
from piezo_fmu_harness.studies.sweep import command as commands  # noqa: E402
from piezo_fmu_harness.engine import ProcessPool, default_jobs  # noqa: E402
from piezo_fmu_harness.fmu import FmuModel, Instance, default_fmu_path, discard  # noqa: E402
from piezo_fmu_harness.studies.sweep.run import execute, open_sweep  # noqa: E402


def frequency_response(model: FmuModel, out: Path, jobs: int) -> dict:
    args = cli._parser().parse_args(["frequency-response", "--out", str(out), "--force"])
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        spec = frequency_spec(args, model, instance)
    finally:
        instance.free()
    run = fr.open_frequency_run(model, spec, out, resume=False, force=True)
    run.begin()
    begin = time.perf_counter()
    fr.execute(run, ProcessPool(model, unzipdir, min(jobs, len(fr.CHAINS))), progress=False)
    simulation_s = time.perf_counter() - begin
    begin = time.perf_counter()
    result = frequency_results.finish(model, run, jobs)
    outputs_s = time.perf_counter() - begin
    discard(unzipdir)
    records = list(run.done.values())
    chains = {}
    for chain, (damper, direction) in enumerate(fr.CHAINS):
        mine = [r for r in records if r["index"] // len(spec.ratios) == chain]
        chains[f"{damper}, {direction}"] = {"cpu_s": sum(r["cpu_seconds"] for r in mine),
                                           "not_settled": sum(not r["settled"] for r in mine)}
    window = spec.settings.window_cycles
    cycles = {"all": sum(r["cycles"] + (0 if r["settled"] else window) for r in records),
              "stability": sum(r["stability_cycles"] for r in records),
              "search": sum(r["escape_cycles"] for r in records),
              "window": sum(window for r in records if not r["settled"])}
    cycles["shooting"] = cycles["all"] - cycles["stability"] - cycles["search"] - cycles["window"]
    escaping = [r for r in records if r["unstable_orbits"]]
    return {"points": len(records), "wall_s": simulation_s, "points_per_s": len(records) / simulation_s,
            "cycles": cycles, "points_with_unstable_orbits": len(escaping),
            "their_cpu_s": sum(r["cpu_seconds"] for r in escaping),
            "worker_cpu_s": sum(r["cpu_seconds"] for r in records), "outputs_s": outputs_s,
            "point_cpu_s_median": statistics.median(r["cpu_seconds"] for r in records),
            "cycles_median": statistics.median(r.get("cycles") or 0 for r in records),
            "chains": chains, "summary": result["summary"]}


def free_decay(model: FmuModel, out: Path, jobs: int) -> dict:
    args = cli._parser().parse_args(["sweep", "--preset", "figs4-9", "--out", str(out)])
    sweeps, _, _ = commands.sweep_specs(args, model)
    runs = [open_sweep(model, spec, folder, resume=False, force=True) for _, spec, folder in sweeps]
    for run in runs:
        run.begin()
    unzipdir = model.extract()
    begin = time.perf_counter()
    execute(runs, ProcessPool(model, unzipdir, jobs), progress=False)
    wall = time.perf_counter() - begin
    discard(unzipdir)
    records = [r for run in runs for r in run.done.values()]
    return {"points": len(records), "wall_s": wall, "points_per_s": len(records) / wall,
            "worker_cpu_s": sum(r["cpu_seconds"] for r in records)}


def optimisation(model: FmuModel, out: Path, jobs: int) -> dict:
    begin = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the command's report; the figures are read back below
        status = cli.main(["optimize", "--param", "m=0.02:0.2", "--param", "d=0.003:0.01", "--seed", "1",
                           "--jobs", str(jobs), "--out", str(out), "--force", "--no-progress", "--fmu", str(model.path)])
    wall = time.perf_counter() - begin
    if status != 0:
        raise SystemExit(f"optimize failed with status {status}")
    report = json.loads((out / "report.json").read_text())
    return {"command_wall_s": wall, "search": report["search"], "optimum": report["optimum"]["x"],
            "objective": report["optimum"]["objective"], "grid": {k: v for k, v in report["grid"].items()
                                                                    if k != "best"},
            "grid_best": report["grid"]["best"]["objective"], "report_wall_s": report["wall_s"]}


def continuation(model: FmuModel, out: Path, jobs: int) -> dict:
    """The default ``piezo-fmu continuation``: its wall time, points and runs of the period map."""
    begin = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        status = cli.main(["continuation", "--jobs", str(jobs), "--out", str(out), "--force",
                           "--fmu", str(model.path)])
    wall = time.perf_counter() - begin
    if status != 0:
        raise SystemExit(f"continuation failed with status {status}")
    summary = json.loads((out / "summary.json").read_text())
    return {"wall_s": wall, "branches": summary["branches"], "points": summary["points"],
            "evaluations": summary["evaluations"], "evaluations_per_point": summary["evaluations"] / summary["points"],
            "seconds": summary["seconds"], "events": {k: len(v) for k, v in summary["events"].items()}}


def timed_command(argv: list, out: Path) -> tuple[float, dict]:
    """Run ``piezo-fmu ARGV --out OUT --force``; its wall time and ``summary.json``."""
    begin = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = cli.main([*argv, "--out", str(out), "--force"])
    wall = time.perf_counter() - begin
    if status != 0:
        raise SystemExit(f"{argv[0]} failed with status {status}")
    return wall, json.loads((out / "summary.json").read_text())


def bifurcation(model: FmuModel, out: Path, jobs: int) -> dict:
    """The default bifurcation diagram (200 frequencies over 0.5-2 w_n, up and down)."""
    wall, summary = timed_command(["bifurcation", "--jobs", str(jobs), "--fmu", str(model.path)], out)
    return {"wall_s": wall, "points": summary["points"], "classes": {d: {k: c["count"] for k, c in v.items()}
                                                                     for d, v in summary["classes"].items()}}


def basins(model: FmuModel, out: Path, jobs: int) -> dict:
    """The default basin map at 1.2 w_n (101 x 101 starts, in chunks on the batch engine)."""
    wall, summary = timed_command(["basins", "--ratio", "1.2", "--jobs", str(jobs), "--no-progress",
                                   "--fmu", str(model.path)], out)
    chunks = [json.loads(line) for line in (out / "points.jsonl").read_text().splitlines()]
    return {"wall_s": wall, "starts": summary["starts"], "cycles_per_start": sum(c["cycles"] for c in chunks)
            / summary["starts"], "shares": {a["name"]: a["share"] for a in summary["attractors"]}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes")
    parser.add_argument("--fmu", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=None, help="keep the results here")
    args = parser.parse_args()

    model = FmuModel(args.fmu or default_fmu_path())
    load_before = os.getloadavg()
    scratch = None if args.out else Path(tempfile.mkdtemp(prefix="bench_forced_"))
    out = args.out or scratch
    try:
        forced = frequency_response(model, out / "frequency-response", args.jobs)
        decay = free_decay(model, out / "figs4-9", args.jobs)
        optimum = optimisation(model, out / "optimize", args.jobs)
        branches = continuation(model, out / "continuation", args.jobs)
        diagram = bifurcation(model, out / "bifurcation", args.jobs)
        basin = basins(model, out / "basins", args.jobs)
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    report = {"jobs": args.jobs, "cores": os.cpu_count(), "load_average_before": [round(x, 2) for x in load_before],
              "frequency_response": forced, "free_decay_sweep": decay, "optimisation": optimum, "continuation": branches,
              "bifurcation": diagram, "basins": basin,
              "free_decay_points_per_forced_point": decay["points_per_s"] / forced["points_per_s"]}
    if args.out is not None:
        (out / "bench_forced.json").write_text(json.dumps(report, indent=2) + "\n")

    print(f"{args.jobs} workers on {os.cpu_count()} cores; load average before: {report['load_average_before']}")
    print(f"frequency response  {forced['points']} points in {forced['wall_s']:.1f} s wall = "
          f"{forced['points_per_s']:.2f} points/s ({forced['worker_cpu_s']:.1f} s CPU in the workers; a point's median "
          f"{forced['point_cpu_s_median']:.3f} s CPU, {forced['cycles_median']:g} forcing cycles); files and figures "
          f"{forced['outputs_s']:.2f} s more")
    for name, chain in forced["chains"].items():
        print(f"  chain {name:14s} {chain['cpu_s']:6.1f} s CPU, {chain['not_settled']} points undecided (no orbit within the cap)")
    cycles = forced["cycles"]
    print(f"  forcing cycles simulated: {cycles['all']}; shooting (march, Newton, verification, measures) "
          f"{cycles['shooting']}; stability checks {cycles['stability']} = {cycles['stability'] / cycles['shooting']:.2f}"
          f" x the shooting; search on from unstable orbits {cycles['search']} = "
          f"{cycles['search'] / cycles['shooting']:.2f} x; windows of the undecided points {cycles['window']}")
    print(f"  {forced['points_with_unstable_orbits']} points met unstable orbits: {forced['their_cpu_s']:.1f} s of the "
          f"{forced['worker_cpu_s']:.1f} s CPU")
    print(f"free-decay sweep    {decay['points']} points in {decay['wall_s']:.1f} s wall = {decay['points_per_s']:.1f} "
          f"points/s ({decay['worker_cpu_s']:.1f} s CPU): {report['free_decay_points_per_forced_point']:.0f} free-decay "
          "points for the time of one steady state")
    search = optimum["search"]
    print(f"optimisation        perfectibility over (m, d): {search['evaluations']} evaluations in "
          f"{search['generations']} generations, {search['wall_s']:.1f} s wall; grid of the same budget "
          f"{optimum['grid']['evaluations']} points; whole command (reference, search, grid, sensitivity, report) "
          f"{optimum['command_wall_s']:.1f} s")
    print(f"  optimum {optimum['optimum']}: J = {optimum['objective']:.4g}; grid best J = {optimum['grid_best']:.4g}")
    print(f"continuation        default (16 seeds a sweep, 0.5-2 w_n): {branches['wall_s']:.1f} s wall (target < 60 s; "
          f"seeds {branches['seconds']['seeds']:.1f} s, branches {branches['seconds']['branches']:.1f} s), "
          f"{branches['branches']} branches, {branches['points']} points, {branches['evaluations']} runs of the period "
          f"map = {branches['evaluations_per_point']:.1f} a point; events {branches['events']}")
    print(f"bifurcation         default (200 frequencies, up and down): {diagram['wall_s']:.1f} s wall (target < 30 s), "
          f"{diagram['points']} points = {diagram['wall_s'] / diagram['points']:.2f} s a point; classes {diagram['classes']}")
    print(f"basins              default at 1.2 w_n ({basin['starts']} starts): {basin['wall_s']:.1f} s wall (target < 300 s), "
          f"{basin['cycles_per_start']:.0f} forcing cycles a start; shares {basin['shares']}")
    print("\n".join(frequency_results.summary_lines(forced["summary"])))


if __name__ == "__main__":
    main()
