"""Global stability across a band (issue 26): at each frequency, the share of random starts that
reach each attractor (``piezo-fmu fractions``).

- :mod:`.study`: the starts on the batch engine, frequencies in chunks on the sweep engine, the
  attractors named across the band, the FMU's checks, the files;
- :mod:`.figure`: the shares stacked over frequency, and the attractors' amplitudes.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu fractions``."""
    from ...options import engine, many_start_options, model_options, results_folder
    from . import study

    fractions = commands.add_parser(
        "fractions", help="global stability across a band: at each frequency, how likely each motion is",
        description="At each frequency of the band, march --starts random starts (the same draws at every "
                    "frequency: p0 and p0'/w_n uniform within +-SPAN, the impact mass at rest anywhere in the gap) "
                    "on the batch engine until each one's trajectory shows where it goes, and report the share of "
                    "each attractor with its 95%% interval; attractors keep one name across the band. A start "
                    "not resolved within the budget --max-cycles is undecided (chaotic only where the survival "
                    "curve shows that what is left persists); the mean transient lifetime is fitted at every "
                    "frequency. The FMU checks one start of every attractor at every frequency and --confirm "
                    "more. Writes fractions.nc/.csv, transients.csv, summary.json, fractions.png and "
                    "transients.png; chunks of frequencies are appended to points.jsonl (--resume).")
    amplitude = fractions.add_mutually_exclusive_group()
    amplitude.add_argument("--amplitude", type=float, default=None, metavar="M",
                           help="base displacement amplitude Y, m (default 1e-3)")
    amplitude.add_argument("--acceleration", type=float, default=None, metavar="M/S2",
                           help="base acceleration amplitude A, m/s^2 (then Y = A / w^2 at each frequency)")
    for option, kind, metavar, text in (
            ("--ratio-min", float, "R", f"lowest frequency, as w / sqrt(K/M) (default {study.DEFAULTS['ratios'][0]:g})"),
            ("--ratio-max", float, "R", f"highest frequency, as w / sqrt(K/M) (default {study.DEFAULTS['ratios'][1]:g})"),
            ("--count", int, "N", f"frequencies, evenly spaced (default {study.DEFAULTS['count']})"),
            ("--starts", int, "N", f"random starts at each frequency (default {study.DEFAULT_STARTS})"),
            ("--span", float, "M", "half-width of the starts' p0 (m; p0' within +-SPAN sqrt(K/M)); default the gap d")):
        fractions.add_argument(option, type=kind, default=None, metavar=metavar, help=text)
    many_start_options(fractions, study.DEFAULTS["max_cycles"], study.DEFAULT_CONFIRM, "at each frequency")
    model_options(fractions)
    results_folder(fractions, "fractions")
    engine(fractions)
    fractions.set_defaults(run=command)


def command(args) -> int:
    from ...fmu import discard
    import time

    from ...checks import PROG, device, engine_damper, open_model, positive, preflight, whole, worker_count
    from ...periodic.band import frequency_spec
    from ...starts.chunks import backend_for, execute
    from . import study

    model = open_model(args)
    starts = whole(study.DEFAULT_STARTS if args.starts is None else args.starts, "--starts", 1,
                   "at least one start a frequency is needed")
    confirm_count = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                          "the FMU's checks cannot be negative")
    seed = whole(0 if args.seed is None else args.seed, "--seed", 0, "the seed is a whole number >= 0")
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
        args.newton_iterations = None
        band = frequency_spec(args, model, instance, study.DEFAULTS)
        parameters = {**model.defaults(), **band.values}
        engine_damper(parameters, batch, band.ratios, band.settings.samples)
        span = positive(parameters["d"] if args.span is None else args.span, "--span",
                        "the half-width of the starts' p0", "m")
        settings = band.settings
        spec = study.FractionSpec(band.ratios, band.natural, tuple(band.base_amplitude(float(w)) for w in band.omegas),
                                  parameters, starts, span, seed, settings.samples, settings.tolerance,
                                  settings.max_cycles, args.device, confirm_count)
        folder, done, start_over = study.open_fractions(model, spec, args.out, args.resume, args.force)
        backend = backend_for(args, model, unzipdir, instance, jobs)
        begin = time.perf_counter()
        try:
            if not execute("fractions", study.tasks(spec), folder, done, start_over, study.HEADER_FILE,
                           {**spec.to_dict(), "fmu_guid": model.guid}, backend, starts * len(spec.ratios),
                           False if args.no_progress else None, args.device):
                return 130
            marched = time.perf_counter() - begin  # before the FMU's checks
            found, outcome = study.outcome(spec, done)
            checks = study.checks(spec, found, outcome, backend)
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    cycles = sum(record["cycles"] for record in done.values())
    report = study.write(spec, found, outcome, checks, folder, time.perf_counter() - begin, cycles, marched)
    print(f"{PROG} fractions: {report['frequencies']} frequencies x {starts} starts, {len(report['attractors'])} "
          f"attractors: {', '.join(report['attractors'])}")
    checked = report["fmu_checks"]
    print(f"  the FMU, marched from {checked['checked']} of the starts: agrees on {checked['agree']}, parted from the "
          f"batch engine in a chaotic transient on {checked['parted']}, disagrees on {checked['disagree']}")
    print(f"  results in {folder}")
    return 0

