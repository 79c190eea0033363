"""Global stability across a band: at each frequency, the share of random starts that
reach each attractor (``piezo-fmu fractions``).

- :mod:`.study`: the starts on the batch engine, frequencies in chunks on the sweep engine, the
  attractors named across the band, the FMU's checks, the files;
- :mod:`.figure`: the shares stacked over frequency, and the attractors' amplitudes.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu fractions``."""
    from ...options import (drive_options, frequency_options, many_start_options, model_options, results_options,
                            work_options)
    from . import study

    fractions = commands.add_parser(
        "fractions", help="how likely each motion is, at each frequency",
        description="At each frequency of the band, march --starts random starts (the same draws at every "
                    "frequency: p0 and p0'/w_n uniform within +-SPAN, the impact mass at rest anywhere in the gap) "
                    "on the batch engine until each one's trajectory shows where it goes, and report the share of "
                    "each attractor with its 95% interval; attractors keep one name across the band. A start "
                    "not resolved within the budget --max-cycles is undecided (chaotic only where the survival "
                    "curve shows that what is left persists); the mean transient lifetime is fitted at every "
                    "frequency. The FMU checks one start of every attractor across the band and --confirm random "
                    f"starts more. Writes {', '.join(study.FILES)}; what was asked goes to fractions.json and the "
                    "chunks of frequencies to points.jsonl (--resume).")
    drive_options(fractions)
    frequency_options(fractions, study.DEFAULTS)
    fractions.add_argument("--starts", type=int, default=None, metavar="N",
                           help=f"random starts at each frequency (default {study.DEFAULT_STARTS})")
    fractions.add_argument("--span", type=float, default=None, metavar="M",
                           help="half-width of the starts' p0, m (p0' within +-SPAN w_n; default the gap d)")
    many_start_options(fractions, study.DEFAULTS, study.DEFAULT_CONFIRM)
    model_options(fractions)
    results_options(fractions, "fractions", resumable=True)
    work_options(fractions)
    fractions.set_defaults(run=command)


def command(args) -> int:
    from ...fmu import discard
    import time

    from ...checks import PROG, device, engine_damper, open_model, positive, preflight, whole, worker_count
    from ...periodic.band import frequency_spec
    from ...starts.chunks import backend_for, execute
    from ...starts.fmu_checks import sentence
    from ...wording import counted, listed
    from . import study

    model = open_model(args)
    starts = whole(study.DEFAULT_STARTS if args.starts is None else args.starts, "--starts", 1,
                   "at least one start a frequency is needed")
    confirm_count = whole(study.DEFAULT_CONFIRM if args.confirm is None else args.confirm, "--confirm", 0,
                          "the FMU's checks cannot be negative")
    seed = whole(args.seed, "--seed", 0, "the seed is a whole number >= 0")
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        import piezo_fmu.solver.batch as batch
        from piezo_fmu.solver.batch import device_error  # the copy of the FMU just loaded, if it carries one

        device(args.device, device_error)
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
        progress = False if args.no_progress else None
        begin = time.perf_counter()
        try:
            if not execute("fractions", study.tasks(spec), folder, done, start_over, study.HEADER_FILE,
                           {**spec.to_dict(), "fmu_guid": model.guid}, backend, starts * len(spec.ratios),
                           progress, args.device):
                return 130
            marched = time.perf_counter()  # before the FMU's checks
            found, outcome = study.outcome(spec, done)
            checks = study.checks(spec, found, outcome, backend, progress)
            checked = time.perf_counter()
        finally:
            backend.close()
    finally:
        instance.free()
        discard(unzipdir)
    cycles = sum(record["cycles"] for record in done.values())
    times = {"marching_s": marched - begin, "checking_s": checked - marched}
    report = study.write(spec, found, outcome, checks, folder, times, cycles, begin)
    print(f"{PROG} fractions: {counted(report['frequencies'], 'frequency')} x {counted(starts, 'start')} in "
          f"{report['wall_s']:.1f} s ({report['marching_s']:.1f} s marching, {report['checking_s']:.1f} s checking), "
          f"{counted(len(report['attractors']), 'attractor')}: {listed(report['attractors'])}")
    print(f"  {sentence(report['fmu_checks'])}")
    print(f"  results in {folder}")
    return 0

