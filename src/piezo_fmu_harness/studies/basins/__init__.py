"""Basins of attraction: a grid of starts at one frequency, each marched to the
motion it reaches, and the share of the starts each motion takes (``piezo-fmu basins --ratio R``).

- :mod:`.study`: the starts on the batch engine, in chunks on the sweep engine, the attractors,
  the FMU's checks, the files;
- :mod:`.figure`: the map.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu basins``."""
    from ...options import drive_options, many_start_options, model_options, ratio_option, results_options, work_options
    from . import study

    basins = commands.add_parser(
        "basins", help="basins of attraction at one frequency",
        description="At w = R w_n, w_n = sqrt(K/M), start the damper from a grid of p0 against p0' (the impact mass at "
                    "rest in the middle of the gap) and march every start, on the batch engine, until its own "
                    "trajectory shows where it goes (a stable orbit it converges to with that orbit's impacts, the "
                    "motion without impacts once it can never impact again, or, after the budget --max-cycles, "
                    "undecided: chaotic only where the map's survival curve shows that it persists); report each "
                    "attractor's share with its 95% interval, the periods each start took, the mean transient "
                    "lifetime and the uncertainty of the basin boundary. The FMU checks one start of every attractor "
                    f"and --confirm random starts more. Writes {', '.join(study.FILES)}; what was asked goes to "
                    "basins.json and the chunks of starts to points.jsonl (--resume).")
    ratio_option(basins, required=True)
    basins.add_argument("--grid", type=int, default=None, metavar="N",
                        help=f"N x N starts over the default ranges (default {study.DEFAULT_COUNT}; 201 for print)")
    basins.add_argument("--p0", default=None, metavar="LO:HI:N",
                        help="initial displacements of the main mass, m (default -2 to 2 linear amplitudes)")
    basins.add_argument("--dp0", default=None, metavar="LO:HI:N",
                        help="initial velocities of the main mass, m/s (default -2 to 2 linear amplitudes times w)")
    drive_options(basins)
    many_start_options(basins, {"max_cycles": study.DEFAULT_MAX_CYCLES}, study.DEFAULT_CONFIRM)
    model_options(basins)
    results_options(basins, "basins", resumable=True)
    work_options(basins)
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
    from ...fmu import discard
    import time

    from ...checks import PROG, device, engine_damper, open_model, positive, preflight, whole, worker_count
    from ...periodic.band import frequency_spec, linear_transmissibility
    from ...starts.chunks import backend_for, execute
    from ...starts.fmu_checks import confirm, sentence
    from ...wording import counted
    from . import study

    model = open_model(args)
    ratio = positive(args.ratio, "--ratio", "the frequency ratio w / w_n", "")
    count = whole(study.DEFAULT_COUNT if args.grid is None else args.grid, "--grid", 2,
                  "a grid needs at least 2 x 2 starts")
    confirm_count = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                          "the FMU's checks cannot be negative")
    seed = whole(args.seed, "--seed", 0, "the seed is a whole number >= 0")
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        args.ratio_min = args.ratio_max = ratio
        args.count = 1
        band = frequency_spec(args, model, instance, {"ratios": (ratio, ratio), "count": 1,
                                                      "max_cycles": study.DEFAULT_MAX_CYCLES, "fewest": 1})
        parameters = {**model.defaults(), **band.values}
        omega = float(band.omegas[0])
        amplitude = float(band.base_amplitude(omega))
        linear = amplitude * float(linear_transmissibility(omega, parameters["M"], parameters["K"], parameters["C"]))
        span = study.DEFAULT_SPAN * linear
        p0 = grid_option(args.p0, "--p0", (-span, span, count), "m")
        dp0 = grid_option(args.dp0, "--dp0", (-span * omega, span * omega, count), "m/s")
        settings = band.settings
        spec = study.BasinSpec(ratio, omega, amplitude, {**parameters, **band.values}, p0, dp0, settings.samples,
                               settings.tolerance, settings.max_cycles, args.device, confirm_count, seed)
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
        engine_damper(spec.values, batch, [ratio], settings.samples)
        folder, done, start_over = study.open_basins(model, spec, args.out, args.resume, args.force)
        backend = backend_for(args, model, unzipdir, instance, jobs)
        progress = False if args.no_progress else None
        begin = time.perf_counter()
        try:
            if not execute("basins", study.tasks(spec), folder, done, start_over, study.HEADER_FILE,
                           {**spec.to_dict(), "fmu_guid": model.guid}, backend, spec.shape[0] * spec.shape[1],
                           progress, args.device):
                return 130
            marched = time.perf_counter()  # before the FMU's checks
            found, starts = study.outcome(spec, done)
            checks = confirm(backend, starts, study.payloads(spec, found, starts), spec.confirm, spec.seed,
                             what="basins", progress=progress)
            checked = time.perf_counter()
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    report = study.write(spec, found, starts, checks, folder, {"marching_s": marched - begin,
                                                                "checking_s": checked - marched}, begin)
    print(f"{PROG} basins at w/w_n = {ratio:g}: {counted(report['starts'], 'start')} in {report['wall_s']:.1f} s "
          f"({report['marching_s']:.1f} s marching, {report['checking_s']:.1f} s checking)")
    for attractor in report["attractors"]:
        print(f"  {100 * attractor['share']:5.1f}% ({100 * attractor['share_low']:.1f}-"
              f"{100 * attractor['share_high']:.1f}%)  {attractor['name']}")
    edge = report["boundary"]
    print(f"  boundary: {100 * edge['boundary_fraction']:.1f}% of the cells; basin entropy {edge['basin_entropy']:.3f}, "
          f"on the boundary {edge['boundary_basin_entropy']:.3f}")
    print(f"  {sentence(report['fmu_checks'])}")
    print(f"  results in {folder}")
    return 0
