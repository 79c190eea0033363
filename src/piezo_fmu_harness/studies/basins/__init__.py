"""Basins of attraction (issue 23): a grid of starts at one frequency, each marched to the motion it
ends on, and the share of the starts each motion takes (``piezo-fmu basins --ratio R``).

- :mod:`.study`: the starts on the engine, the attractors, the files;
- :mod:`.figure`: the map.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu basins``."""
    from ...options import engine, model_options, results_folder

    basins = commands.add_parser(
        "basins", help="basins of attraction at one frequency: which motion each start ends on, and their shares",
        description="At w = R sqrt(K/M), start the damper from a grid of p0 against p0' (the impact mass at rest in "
                    "the middle of the gap), find the steady state each start ends on (a stable orbit, or a motion "
                    "that is not periodic, classified), and report the share of the starts each attractor takes. "
                    "Writes basins.nc/.csv, summary.json and basins.png; every start is appended to points.jsonl "
                    "(--resume).")
    basins.add_argument("--ratio", type=float, required=True, metavar="R", help="the frequency, as w / sqrt(K/M)")
    basins.add_argument("--p0", default=None, metavar="LO:HI:N",
                        help="initial displacements of the main mass, m (default -2 to 2 linear amplitudes, 15)")
    basins.add_argument("--dp0", default=None, metavar="LO:HI:N",
                        help="initial velocities of the main mass, m/s (default -2 to 2 linear amplitudes times w, 15)")
    basins.add_argument("--amplitude", type=float, default=None, metavar="M", help="base displacement amplitude Y, m "
                                                                                    "(default 1e-3)")
    for option, kind, metavar, text in (
            ("--load", float, "OHM", "load R_load of each patch, Ohm (default 1/(omega_c C_p))"),
            ("--voltage-model", int, "N", "0, 1 or 2 (default 1)"),
            ("--samples", int, "N", "communication steps per forcing period (default 64)"),
            ("--tolerance", float, "TOL", "steady state: the section returns within TOL * Y (default 1e-6)"),
            ("--max-cycles", int, "N", "cap on the forcing cycles simulated per start (default 400)")):
        basins.add_argument(option, type=kind, default=None, metavar=metavar, help=text)
    model_options(basins)
    results_folder(basins, "basins")
    engine(basins)
    basins.set_defaults(run=command)


def grid_option(text, option: str, default: tuple, unit: str) -> tuple:
    from ...spec import UsageError

    if text is None:
        return default
    try:
        lo, hi, count = text.split(":")
        lo, hi, count = float(lo), float(hi), int(count)
    except ValueError:
        raise UsageError(f"{option} {text}: give LO:HI:N ({unit}, N a whole number)") from None
    if count < 1:
        raise UsageError(f"{option} {text}: N = {count} starts is an empty grid; allowed range [1, inf)")
    if not lo <= hi or (count > 1 and lo == hi):
        raise UsageError(f"{option} {text}: {'reversed' if lo > hi else 'empty'} range (give LO < HI, or N = 1)")
    return lo, hi, count


def command(args) -> int:
    import json
    import shutil
    import sys

    from ...checks import PROG, make_backend, open_model, positive, preflight, worker_count
    from ...engine import InProcess
    from ...periodic.band import frequency_spec, linear_transmissibility
    from . import study

    model = open_model(args)
    ratio = positive(args.ratio, "--ratio", "the frequency ratio w / sqrt(K/M)", "")
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        args.ratio_min = args.ratio_max = ratio
        args.count, args.acceleration, args.newton_iterations = 1, None, None
        band = frequency_spec(args, model, instance, {"ratios": (ratio, ratio), "count": 1, "max_cycles": 400, "fewest": 1})
        parameters = {**model.defaults(), **band.values}
        omega, amplitude = float(band.omegas[0]), float(band.amplitude)
        linear = amplitude * float(linear_transmissibility(omega, parameters["M"], parameters["K"], parameters["C"]))
        span = study.DEFAULT_SPAN * linear
        p0 = grid_option(args.p0, "--p0", (-span, span, study.DEFAULT_COUNT), "m")
        dp0 = grid_option(args.dp0, "--dp0", (-span * omega, span * omega, study.DEFAULT_COUNT), "m/s")
        spec = study.BasinSpec(ratio, omega, amplitude, band.values, p0, dp0, band.settings)
        folder, done, start_over = study.open_basins(model, spec, args.out, args.resume, args.force)
        header = json.dumps({**spec.to_dict(), "fmu_guid": model.guid}, indent=2) + "\n"
        remaining = len(spec.grid()) - len(done)
        if remaining:
            backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                       else make_backend(args, model, unzipdir, jobs))
            print(f"{PROG} basins: {remaining} of {len(spec.grid())} starts to run on {backend.description}",
                  file=sys.stderr)
            try:
                study.execute(spec, folder, done, start_over, header, backend)
            except KeyboardInterrupt:
                print(f"\n{PROG} basins: interrupted; {len(done)} starts are saved; run the same command with --resume",
                      file=sys.stderr)
                return 130
            finally:
                backend.close()
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    report = study.write(spec, done, folder)
    print(f"{PROG} basins at w/w_n = {ratio:g}: {report['starts']} starts")
    for attractor in report["attractors"]:
        print(f"  {100 * attractor['share']:5.1f}%  {attractor['name']}")
    print(f"  results in {folder}")
    return 0
