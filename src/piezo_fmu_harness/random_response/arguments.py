"""The random excitation on the command line, written once for the commands that march it
(``piezo-fmu random``, ``piezo-fmu optimize --objective random``): the options that describe the
excitation and its realizations (:func:`excitation_options`), their checks, and the
:class:`~.spec.RandomSpec` they ask for (:func:`excitation_spec`). Every bad option is refused
before any work, naming the option, the value and what is allowed.

A command adds what is its own: ``random`` a recorded acceleration (``--record``), several levels
(``--levels``), an envelope, its communication step and the FMU's checks; ``optimize`` the search.
"""

from __future__ import annotations

import math

from .spec import SETTLED, RandomSpec, build_source, default_warmup

#: The kinds ``--psd`` names (anything else is a CSV file's path).
PSD_KINDS = ("white", "kanai-tajimi", "clough-penzien")
#: The spectrum's level by default, (m/s^2)^2/Hz: Kanai-Tajimi firm soil of RMS 0.28 m/s^2 (0.03 g), whose
#: response without the damper (RMS 3.3 mm for the nominal damper) reaches the 8 mm gap.
DEFAULT_LEVEL = 0.01
#: White noise's band by default, Hz.
DEFAULT_BAND = (0.5, 25.0)
#: The input's step by default: this many steps a period of the spectrum's highest frequency.
STEPS_PER_TOP = 10
#: Realizations and the window (s) by default, by command: an optimisation marches them all for each design.
REALIZATIONS_AND_WINDOW = {"random": (1000, 300.0), "optimize": (50, 60.0)}
#: The FMU's start state of every realization: at rest (the base too, ``y = 0``).
START = {"p0": 0.0, "q0": 0.0, "dp0": 0.0, "dq0": 0.0}
#: The most hold steps one realization may take, warm-up and window together: a run no machine
#: finishes (the default warm-up of a main mass damped at 1e-90 N.s/m is 1e90 s) is refused before any work.
MAX_STEPS = 1e9
#: The voltage model by default, and those the batch engine carries.
VOLTAGE_MODEL, VOLTAGE_MODELS = 2, (0, 2)


def excitation_options(sub, source=None, level=None) -> None:
    """``--psd`` (in ``source``, a mutually exclusive group, when given), ``--level`` (in ``level``),
    ``--band``, the ground filters' options, ``--realizations``, ``--duration``, ``--warmup`` and
    ``--f-low``. Each help states both commands' defaults: an option means one thing everywhere."""
    (source or sub).add_argument(
        "--psd", default="kanai-tajimi", metavar="{white,kanai-tajimi,clough-penzien,FILE.csv}",
        help="the PSD of the base acceleration: a kind, or a CSV table (frequency Hz, PSD (m/s^2)^2/Hz, interpolated "
             "log-log) (default kanai-tajimi)")
    (level or sub).add_argument(
        "--level", type=float, default=None, metavar="G0",
        help="the PSD's level, one-sided, (m/s^2)^2/Hz: white noise's and the ground filters' G0, a table's largest "
             f"value (default {DEFAULT_LEVEL:g}; a table as it is)")
    sub.add_argument("--band", type=float, nargs=2, default=None, metavar=("FMIN", "FMAX"),
                     help="Hz: white noise's band; for the ground filters and a table, 0 and the cut (default "
                          f"{DEFAULT_BAND[0]:g} {DEFAULT_BAND[1]:g} for white noise, 0 25 for the ground filters, a "
                          "table's last frequency)")
    sub.add_argument("--soil", choices=("firm", "medium", "soft"), default="firm",
                     help="the ground filters' preset (Kanai-Tajimi, Clough-Penzien) (default firm)")
    for option, metavar, text in (("--omega-g", "RAD/S", "the ground's frequency, rad/s (default the soil's)"),
                                  ("--zeta-g", "Z", "the ground's damping ratio (default the soil's)"),
                                  ("--omega-f", "RAD/S", "Clough-Penzien's high-pass frequency, rad/s (default the soil's)"),
                                  ("--zeta-f", "Z", "Clough-Penzien's high-pass damping ratio (default the soil's)")):
        sub.add_argument(option, type=float, default=None, metavar=metavar, help=text)
    (study, window), (optimization, short) = REALIZATIONS_AND_WINDOW["random"], REALIZATIONS_AND_WINDOW["optimize"]
    sub.add_argument("--realizations", type=int, default=None, metavar="N",
                     help=f"realizations, drawn with --seed (default {study}, 1 with --record; {optimization} for "
                          "optimize)")
    sub.add_argument("--duration", type=float, default=None, metavar="S",
                     help=f"the window analysed, s, after the warm-up (default {window:g}, a record's length less the "
                          f"warm-up; {short:g} for optimize)")
    sub.add_argument("--warmup", type=float, default=None, metavar="S",
                     help="the warm-up discarded, s (default: until the linear oscillator's transient variance is 0.1%% "
                          "of its stationary one, ln(1000) / (2 zeta w_n), for optimize the longest any design within "
                          "the bounds needs; 0 with --record)")
    sub.add_argument("--f-low", type=float, default=None, metavar="HZ",
                     help="the high-pass corner of the low-frequency treatment, Hz (default 0.1, or half the band's "
                          "start where lower)")


def source_of(args) -> tuple[dict, tuple]:
    """The excitation's kind and parameters, and its levels (``--record`` and ``--levels`` where
    the command has them)."""
    from ..excitation import CLOUGH_PENZIEN_SOILS, KANAI_TAJIMI_SOILS, Record, TablePSD
    from ..spec import UsageError

    record, several = getattr(args, "record", None), getattr(args, "levels", None)
    if record is not None:
        if args.level is not None or several is not None:
            raise UsageError(f"--record {record}: a record has no level; allowed: --level or --levels with --psd")
        try:
            recorded = Record.from_csv(record)
        except (OSError, ValueError) as error:
            raise UsageError(f"--record {record}: {error}") from None
        return {"kind": "record", "step": recorded.step, "acceleration": recorded.acceleration.tolist(),
                "name": str(record)}, ()
    if several is not None:
        try:
            levels = tuple(float(text) for text in several.split(","))
        except ValueError:
            raise UsageError(f"--levels {several}: give levels as G1,G2,... ((m/s^2)^2/Hz, each > 0)") from None
    else:
        levels = (DEFAULT_LEVEL if args.level is None else args.level,)
    bad = [g for g in levels if not (math.isfinite(g) and g > 0.0)]
    if bad:
        raise UsageError(f"--level(s) {bad[0]!r}: a one-sided PSD level must be a finite number > 0; allowed range "
                         "(0, inf) (m/s^2)^2/Hz")
    kind = args.psd
    band = args.band
    if kind == "white":
        fmin, fmax = DEFAULT_BAND if band is None else band
        return {"kind": "white", "fmin": fmin, "fmax": fmax}, levels
    if band is not None and band[0] != 0.0:
        raise UsageError(f"--band {band[0]:g} {band[1]:g}: the ground filters and a table start where they start; "
                         "allowed: --band 0 FMAX (FMAX the cut, Hz); the low-frequency treatment is --f-low")
    upper = 25.0 if band is None else band[1]
    if kind in ("kanai-tajimi", "clough-penzien"):
        preset = (KANAI_TAJIMI_SOILS if kind == "kanai-tajimi" else CLOUGH_PENZIEN_SOILS)[args.soil]
        source = {"kind": kind, "omega_g": args.omega_g or preset[0], "zeta_g": args.zeta_g or preset[1],
                  "upper": upper}
        if kind == "clough-penzien":
            source.update(omega_f=args.omega_f or preset[2], zeta_f=args.zeta_f or preset[3])
        return source, levels
    try:
        table = TablePSD.from_csv(kind, upper=math.nan if band is None else upper)
    except (OSError, ValueError) as error:
        raise UsageError(f"--psd {kind}: {error}; allowed: one of {', '.join(PSD_KINDS)}, or a CSV table") from None
    if args.level is None and several is None:
        levels = (table.level,)
    return {"kind": "table", "frequencies": table.frequencies.tolist(), "densities": table.densities.tolist(),
            "upper": table.upper, "name": str(kind)}, levels


def damper_values(args, model, instance, given: dict) -> dict:
    """The FMU parameters of the damper every realization is marched with: the FMU's defaults and
    ``given`` (``--set``), from rest, the voltage model (``--voltage-model``, 0 or 2) and the load
    (``--load``, else the circuit's estimate of the optimum for these values)."""
    from ..checks import load_value
    from ..circuit import optimum_load
    from ..spec import UsageError, check_with_fmu

    values = {**model.defaults(), **given}
    starts = {name: given[name] for name in START if given.get(name, 0.0) != 0.0}
    if starts:
        raise UsageError(f"--set {', '.join(f'{k}={v!r}' for k, v in starts.items())}: every realization starts from rest, "
                         "with the base; allowed: 0 (or leave it out)")
    values.update(START)
    values["voltage_model"] = VOLTAGE_MODEL if args.voltage_model is None else args.voltage_model
    if values["voltage_model"] not in VOLTAGE_MODELS:
        raise UsageError(f"--voltage-model {values['voltage_model']}: the batch engine carries a patch's voltage only "
                         "where it acts back on the barrier; allowed: 0 (quasi-static, nothing harvested) or 2 (the "
                         "coupled circuit)")
    if args.load is not None:
        values["R_load"] = load_value(model, args.load, "--load")
    checked = {**given, "voltage_model": values["voltage_model"]}
    if args.load is not None:
        checked["R_load"] = values["R_load"]
    check_with_fmu(model, instance, [checked], "--set")  # before anything is derived from the values
    if args.load is None and "R_load" not in given:
        values["R_load"] = optimum_load(instance, values)
    if not values["C"] > 0.0:
        raise UsageError(f"--set: C = {values['C']!r} N.s/m: without damping the main mass's response to a stationary "
                         "input never settles (its variance grows without end); allowed range (0, inf) N.s/m")
    return values


def excitation_spec(args, values: dict, command: str, slowest: dict | None = None) -> RandomSpec:
    """The spec the excitation options ask for, every option checked: the damper ``values``
    (:func:`damper_values`), the realizations and the window of ``command`` by default
    (:data:`REALIZATIONS_AND_WINDOW`); the warm-up by default is the one the damper ``slowest``
    needs (``values`` unless given). ``args`` has ``--step`` (the command's own) and ``--seed``."""
    from ..checks import positive, whole
    from ..excitation import Excitation
    from ..spec import UsageError

    source, levels = source_of(args)
    realizations, duration = REALIZATIONS_AND_WINDOW[command]
    record = source["kind"] == "record"
    if record:
        step = source["step"]
        if args.step is not None and abs(args.step - step) > 1e-6 * step:
            raise UsageError(f"--step {args.step!r}: a record is marched at its own step, {step!r} s; allowed: "
                             "that step (resample the record to another)")
        count = whole(1 if args.realizations is None else args.realizations, "--realizations", 1, "")
        if count != 1:
            raise UsageError(f"--realizations {count}: a record is one realization; allowed: 1")
    else:
        top = source["fmax"] if source["kind"] == "white" else source["upper"]
        step = positive(1.0 / (STEPS_PER_TOP * top) if args.step is None else args.step, "--step",
                        "the input's step", "s")
        count = whole(realizations if args.realizations is None else args.realizations, "--realizations", 1,
                      "at least one realization")
    try:
        excitation = Excitation(build_source(source, levels[0] if levels else None), step=step, f_low=args.f_low)
    except ValueError as error:
        raise UsageError(f"--psd/--band/--step/--f-low: {error}") from None
    f_low = excitation.f_low
    if args.warmup is not None:
        warmup = args.warmup
        if not (math.isfinite(warmup) and warmup >= 0.0):
            raise UsageError(f"--warmup {warmup!r}: allowed range [0, inf) s")
    else:
        warmup = 0.0 if record else default_warmup(slowest or values, f_low)
    if args.duration is not None:
        window = positive(args.duration, "--duration", "the window analysed", "s")
    elif record:
        window = len(source["acceleration"]) * step - warmup
        if window <= 0.0:
            raise UsageError(f"--warmup {warmup:g}: the record lasts {len(source['acceleration']) * step:g} s; allowed: "
                             "a warm-up shorter than the record")
    else:
        window = duration
    if window < 2.0 * step:
        raise UsageError(f"--duration {window:g}: the window must hold two steps of {step:g} s at least")
    steps = (warmup + window) / step
    if not steps <= MAX_STEPS:
        why = advice = ""
        if args.warmup is None and not record and slowest is None:  # C / 2M = zeta w_n sets the default
            why = f", the default: the linear oscillator's settling ln(1000) / (2 zeta w_n) for C = {values['C']:g} N.s/m"
            room = MAX_STEPS * step - window
            if room > 0.0:
                advice = f", or --set C of at least {values['M'] * math.log(1.0 / SETTLED) / room:.3g} N.s/m"
        raise UsageError(f"--warmup/--duration/--step: {warmup:g} s of warm-up{why}, and a window of {window:g} s, "
                         f"make {steps:.3g} steps of {step:g} s a realization; allowed: at most {MAX_STEPS:g} (give a "
                         f"shorter --warmup or --duration, or a longer --step{advice})")
    seed = whole(0 if args.seed is None else args.seed, "--seed", 0, "the seed is a whole number >= 0")
    return RandomSpec(source, levels, values, count, float(window), float(warmup), float(step), float(f_low),
                      seed=seed, confirm=0)
