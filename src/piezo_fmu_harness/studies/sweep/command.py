"""The paper's studies on the command line: ``piezo-fmu nominal``, ``two-designs`` and ``sweep``."""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import Optional

from ...fmu import discard
from ...checks import (
    PROG,
    assignments,
    interrupt,
    make_backend,
    open_model,
    preflight,
    times,
    worker_count,
)
from ...spec import DEFAULT_SWEEP_STEP, UsageError
from ...wording import counted
from . import presets


def sweep_specs(args, model) -> tuple[list[tuple[str, object, Path]], Optional[dict], Path]:
    """The sweeps asked for: ``[(name, spec, folder)]``, the panels of a preset set, and OUT."""
    from ...spec import build_spec, load_toml, parse_grid

    sources = [bool(args.preset), bool(args.config)]
    if sum(sources) > 1:
        raise UsageError("give either --preset or --config, not both")
    config = load_toml(model, args.config) if args.config else {}
    stop_time, step = times(args, DEFAULT_SWEEP_STEP, config)
    cli_axes = [parse_grid(model, text) for text in args.grid]
    cli_fixed = assignments(model, args.set)

    if args.preset in presets.PRESET_SETS:
        panels = presets.PRESET_SETS[args.preset]["panels"]
        names = list(panels.values())
    elif args.preset:
        panels, names = None, [args.preset]
    else:
        panels, names = None, [None]
    out = args.out or (Path(config["out"]) if "out" in config else None)
    if out is None:
        out = Path("results") / (args.preset or "sweep")

    sweeps = []
    for name in names:
        if name is None:
            axes, fixed = list(config.get("axes", [])), dict(config.get("fixed", {}))
        else:
            preset = presets.PRESETS[name]
            axes = [parse_grid(model, text) for text in preset["grid"]]
            fixed = assignments(model, preset["set"])
        by_name = {axis.name: axis for axis in axes}
        for axis in cli_axes:
            by_name[axis.name] = axis
            fixed.pop(axis.name, None)
        fixed.update(cli_fixed)
        spec = build_spec(list(by_name.values()), fixed, stop_time, step,
                          name or config.get("name") or Path(out).name)
        folder = Path(out) / name if panels else Path(out)
        sweeps.append((name or spec.name, spec, folder))
    return sweeps, panels, Path(out)


def sweep(args) -> int:
    from . import analysis
    from .run import display, execute, open_sweep, write_results

    model = open_model(args)
    sweeps, panels, out = sweep_specs(args, model)
    jobs = worker_count(args)
    quantile = analysis.DEFAULT_ZONE_QUANTILE if args.zone_quantile is None else args.zone_quantile
    if not 0.0 < quantile < 1.0:
        raise UsageError(f"--zone-quantile {quantile:g}: must lie between 0 and 1")
    if args.damping == "ls" and "damping_inclination_ls" not in model.outputs:
        raise UsageError(f"--damping ls: the FMU {model.path} lacks the output damping_inclination_ls (an FMU "
                         "built before it); rebuild it, or rank by eq. 29 (--damping eq29)")

    runs = [open_sweep(model, spec, folder, args.resume, args.force) for _, spec, folder in sweeps]
    corners = [spec.values_at(c) for _, spec, _ in sweeps for c in grid_corners(spec)]
    unzipdir, instance = preflight(model, corners, "sweep grid")
    instance.free()

    remaining = sum(len(run.todo()) for run in runs)
    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        if remaining:
            backend = make_backend(args, model, unzipdir, min(jobs, remaining))
        for run in runs:
            run.begin()
        if remaining:
            total = sum(run.spec.size for run in runs)
            print(f"{PROG} sweep: {remaining} of {counted(total, 'point')} to run on {backend.description} "
                  f"({runs[0].spec.stop_time:g} s each, communication step {runs[0].spec.step:g} s)",
                  file=sys.stderr)
            try:
                execute(runs, backend, progress=False if args.no_progress else None)
            except KeyboardInterrupt:
                finished = sum(len(run.done) for run in runs)
                print(f"\n{PROG} sweep: interrupted; {finished} of {counted(total, 'point')} are saved in "
                      f"{', '.join(str(run.store.path) for run in runs)}; run the same command with "
                      "--resume to finish", file=sys.stderr)
                return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        discard(unzipdir)

    names = [name for name, _, _ in sweeps]
    results = write_results(model, runs, names, panels, out, quantile, args.damping, jobs)
    for name, run in zip(names, runs):
        print("\n".join(analysis.zone_summary_lines(results[name]["zones"], display(results[name]["dataset"]))))
        failed = int((results[name]["dataset"]["status"] == "error").sum())
        if failed:
            print(f"  {counted(failed, 'point')} rejected by the FMU (status 'error' in {run.folder / 'sweep.csv'})")
        print(f"  results in {run.folder}")
    if panels:
        print(f"Figs. 4-9 in {out}")
    return 0


def grid_corners(spec) -> list[dict]:
    """The grid corners the FMU checks first (all of them up to 6 axes, else the two extremes)."""
    if len(spec.axes) <= 6:
        return list(spec.corners())
    return [{a.name: a.values[0] for a in spec.axes}, {a.name: a.values[-1] for a in spec.axes}]
