"""A band of harmonic base motion, as the studies of the forced response ask for it: the band
and its options (:func:`frequency_spec`), the steady state at one frequency as a task of the sweep
engine (:func:`solve_point`), and the closed form of the main mass alone.

The base moves as ``y = Y sin(w t)``, ``Y`` given directly or as ``A / w^2`` for an acceleration
amplitude ``A``; ``w`` runs over ``count`` evenly spaced values between ``ratio_min`` and
``ratio_max`` times ``sqrt(K/M)``. Without the damper, the gap is widened until the impact mass
cannot reach a barrier, as for Fig. 3a.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Optional

import numpy as np

from ..fmu import FmuRunError, Instance
from .drive import STATE_PARAMETERS, HarmonicDrive
from .steady_state import Settings, SteadyState

DAMPER_CASES = ("with", "without")


#: The band's defaults: w / sqrt(K/M) from 0.5 to 2 at 61 frequencies (at least 60, and sqrt(K/M)
#: itself one of them, a step of 0.025), at most 400 cycles each, at least 2 frequencies.
BAND_DEFAULTS = {"ratios": (0.5, 2.0), "count": 61, "max_cycles": 400, "fewest": 2}


#: Base displacement amplitude (m): the no-damper response at sqrt(K/M) would be 1/(2 zeta) = 316
#: times it, so 1 mm makes the nominal damper impact over a band around resonance.
DEFAULT_AMPLITUDE = 1e-3


DEFAULT_VOLTAGE_MODEL = 1


@dataclass(frozen=True)
class FrequencySpec:
    """A frequency-response study (SI).

    Attributes
    ----------
    ratios : tuple
        Frequency ratios ``w / sqrt(K/M)``, increasing.
    natural : float
        ``sqrt(K/M)``, rad/s.
    amplitude, acceleration : float or None
        Base displacement amplitude ``Y`` (m), or acceleration amplitude ``A`` (m/s^2); one is set.
    values : dict
        FMU parameters of the damper (``--set``, ``voltage_model``, ``R_load``).
    wide_gap : float
        Gap ``d`` (m) of the runs without the damper.
    settings : Settings
        How each steady state is found.
    """

    ratios: tuple
    natural: float
    amplitude: Optional[float]
    acceleration: Optional[float]
    values: dict
    wide_gap: float
    settings: Settings = field(default_factory=Settings)

    @property
    def omegas(self) -> np.ndarray:
        return np.array(self.ratios) * self.natural

    def base_amplitude(self, omega: float) -> float:
        """``Y`` (m) at ``omega`` (rad/s)."""
        return self.amplitude if self.amplitude is not None else self.acceleration / omega**2

    def chain_values(self, damper: str) -> dict:
        return dict(self.values) if damper == "with" else {**self.values, "d": self.wide_gap}

    def sequence(self, direction: str) -> list[int]:
        """Frequency indices in the order a chain visits them."""
        indices = list(range(len(self.ratios)))
        return indices if direction == "up" else indices[::-1]

    def index(self, chain: int, frequency: int) -> int:
        """The record index of a point: unique over the four chains."""
        return chain * len(self.ratios) + frequency

    def to_dict(self) -> dict:
        return {"ratios": list(self.ratios), "natural_rad_per_s": self.natural, "amplitude_m": self.amplitude,
                "acceleration_m_per_s2": self.acceleration, "values": dict(self.values),
                "wide_gap_m": self.wide_gap, "settings": asdict(self.settings)}


def wide_gap(spec_amplitude: float, peak_transmissibility: float) -> float:
    """A gap (m) the impact mass of the runs without the damper cannot cross: the nominal case's
    1 m, or four times the largest linear amplitude when that is larger."""
    return max(1.0, 4.0 * spec_amplitude * peak_transmissibility)


#: The largest linear transmissibility a band may reach: beyond it the main mass is undamped within
#: rounding of its resonance (``1 / |1 - r^2|`` for ``C = 0``, ``r`` given to 12 digits).
UNBOUNDED = 1e12


def linear_transmissibility(omega, M: float, K: float, C: float):
    """``|X/Y|`` of the base-excited oscillator (absolute displacement over base amplitude), from the
    frequency ratio ``r = w / sqrt(K/M)`` and ``2 zeta r = C w / K``, so that no square leaves double
    range (a spring of 1e-300 N/m: ``K^2`` is 0)."""
    omega = np.asarray(omega, float)
    natural = math.sqrt(K / M)
    ratio = omega / natural if natural > 0.0 else np.zeros_like(omega)  # sqrt(K/M) is 0: so is every w
    damping = C * omega / K
    return np.hypot(1.0, damping) / np.hypot(1.0 - ratio * ratio, damping)


def solve_point(instance: Instance, index: int, values: dict, omega: float, amplitude: float,
                settings: Settings, state, phase: float) -> dict:
    """The steady state at ``omega`` from the guess ``(state, phase)``: a JSON-safe record (a
    task of the sweep engine)."""
    begin, begin_cpu = time.perf_counter(), time.process_time()
    record = {"index": index, "omega": omega, "base_amplitude": amplitude}
    try:
        drive = HarmonicDrive(instance, values, omega, amplitude, settings.samples)
        record.update(status="ok", error=None, **SteadyState(drive, settings).solve(state, phase))
    except FmuRunError as error:
        record.update(status="error", error=str(error), settled=False)
    record["seconds"] = time.perf_counter() - begin
    record["cpu_seconds"] = time.process_time() - begin_cpu
    return record


def rest_state() -> list[float]:
    """The guess of a chain's first point: everything at rest (``p = q = 0``)."""
    return [0.0] * len(STATE_PARAMETERS)


def solve_chain(instance: Instance, points, settings: Settings) -> list[dict]:
    """A sweep in one process: the steady state at each of ``points`` (``(values, omega, amplitude)``
    in SI, in the sweep's order), each from the previous one's final state, from rest; a point the
    FMU rejects leaves the guess as it was."""
    state, phase, records = rest_state(), 0.0, []
    for index, (values, omega, amplitude) in enumerate(points):
        record = solve_point(instance, index, values, omega, amplitude, settings, state, phase)
        if record.get("status") == "ok":
            state, phase = record["state"], record["phase"]
        records.append(record)
    return records


#: What each option that caps the periods of a study means (:mod:`piezo_fmu_harness.options`).
CAPS = {"--cycles-per-frequency": "the forcing periods simulated at one frequency",
        "--max-cycles": "the budget of periods a start is marched"}


def cap_option(args) -> str:
    """The option that caps the periods of the study ``args`` asks for: the forced response's
    ``--cycles-per-frequency``, or the studies of many starts' budget ``--max-cycles``."""
    return "--cycles-per-frequency" if hasattr(args, "cycles_per_frequency") else "--max-cycles"


def given_cap(args) -> Optional[int]:
    return getattr(args, cap_option(args)[2:].replace("-", "_"), None)


def frequency_spec(args, model, instance, defaults: Optional[dict] = None, searched: tuple = ()):
    """The study the options ask for, checked (values, ranges, and the FMU's own checks);
    ``searched`` parameters (the optimiser's) are left out of the FMU's checks. ``defaults``: the
    band's (:data:`piezo_fmu_harness.periodic.band.BAND_DEFAULTS` unless given)."""
    from ..checks import assignments, load_value, positive, whole
    from ..circuit import default_load
    from ..spec import UsageError, check_with_fmu

    defaults = defaults or BAND_DEFAULTS
    overrides = assignments(model, args.set)
    for name in overrides:
        if name in STATE_PARAMETERS:
            raise UsageError(f"--set {name}: the initial state is what the shooting sets at each frequency; "
                             f"it cannot be set (the settable parameters exclude {', '.join(STATE_PARAMETERS)})")
        if name in ("R_load", "voltage_model"):
            raise UsageError(f"--set {name}: give the load and the voltage model with --load and --voltage-model")
    if getattr(args, "acceleration", None) is not None:
        amplitude, acceleration = None, positive(args.acceleration, "--acceleration", "the base acceleration "
                                                  "amplitude A", "m/s^2")
    else:
        amplitude = positive(DEFAULT_AMPLITUDE if args.amplitude is None else args.amplitude, "--amplitude",
                              "the base displacement amplitude Y", "m")
        acceleration = None
    lo = positive(defaults["ratios"][0] if args.ratio_min is None else args.ratio_min, "--ratio-min",
                   "the lowest frequency ratio w / sqrt(K/M)", "")
    hi = positive(defaults["ratios"][1] if args.ratio_max is None else args.ratio_max, "--ratio-max",
                   "the highest frequency ratio w / sqrt(K/M)", "")
    count = whole(defaults["count"] if args.count is None else args.count, "--count", defaults["fewest"],
                   f"need at least {defaults['fewest']} frequenc{'y' if defaults['fewest'] == 1 else 'ies'}")
    if count == 1 and lo != hi:
        raise UsageError(f"--count 1 needs --ratio-min = --ratio-max (one frequency); got {lo:g} and {hi:g}")
    if count > 1 and not lo < hi:
        raise UsageError(f"--ratio-min {lo:g} is not below --ratio-max {hi:g}: "
                         f"{'reversed' if lo > hi else 'empty'} range of frequencies (give RATIO_MIN < RATIO_MAX)")
    cap = defaults["max_cycles"]
    defaults = Settings()
    samples = whole(defaults.samples if args.samples is None else args.samples, "--samples", 16,
                     "need at least 16 communication steps per forcing period")
    tolerance = defaults.tolerance if args.tolerance is None else args.tolerance
    if not (math.isfinite(tolerance) and 0 < tolerance <= 1e-2):
        raise UsageError(f"--tolerance {tolerance:g}: the steady-state tolerance (relative to Y) must lie in "
                         "(0, 0.01]")
    cycles = whole(cap if given_cap(args) is None else given_cap(args), cap_option(args), 10,
                    f"{CAPS[cap_option(args)]} must be at least 10")
    iterations = getattr(args, "newton_iterations", None)
    newton = whole(defaults.newton_iterations if iterations is None else iterations,
                    "--newton-iterations", 0, "the Newton iterations cannot be negative")
    parameter = model.parameters["voltage_model"]
    try:
        voltage_model = parameter.coerce(DEFAULT_VOLTAGE_MODEL if args.voltage_model is None else args.voltage_model)
    except ValueError as error:
        raise UsageError(f"--voltage-model {args.voltage_model}: {error}") from None
    values = {**overrides, "voltage_model": voltage_model}
    if args.load is not None:
        values["R_load"] = load_value(model, args.load, "--load")
    check_with_fmu(model, instance, [values], "--set")  # before anything is derived from the values
    if args.load is None:
        values["R_load"] = default_load(instance, values)
    checked = {name: value for name, value in values.items() if name not in searched}
    parameters = {**model.defaults(), **values}
    natural = math.sqrt(parameters["K"] / parameters["M"])
    if not natural > 0.0:
        raise UsageError(f"--set K = {parameters['K']!r} N/m, M = {parameters['M']!r} kg: sqrt(K/M) is 0 rad/s in "
                         "double precision, and the studies force at multiples of it; allowed: K/M >= 5e-324 1/s^2")
    ratios = tuple(float(f"{r:.12g}") for r in (np.linspace(lo, hi, count) if count > 1 else [lo]))
    peak_y = amplitude if amplitude is not None else acceleration / (lo * natural) ** 2
    with np.errstate(divide="ignore"):
        fine, at = (linear_transmissibility(np.asarray(r) * natural, parameters["M"], parameters["K"], parameters["C"])
                    for r in (np.linspace(lo, hi, 4001), ratios))
    peak = float(np.max(fine, where=fine <= UNBOUNDED, initial=0.0))  # a fine point at an undamped resonance aside
    if not np.all(at <= UNBOUNDED):
        least = math.sqrt(parameters["K"] * parameters["M"]) / UNBOUNDED  # C at which K / (C w_n) is UNBOUNDED
        raise UsageError(f"--set C = {parameters['C']!r} N.s/m with w/w_n = {ratios[int(np.argmax(at))]:g} among the "
                         "frequencies: the main mass alone, (all but) undamped, has no bounded response at its "
                         "resonance, and the studies measure against it (the runs without the damper, the motion "
                         f"without impacts, a basin grid's span); allowed: C >= {least:.3g} N.s/m, or frequencies "
                         "that leave out w/w_n = 1")
    spec = FrequencySpec(ratios=ratios, natural=natural, amplitude=amplitude, acceleration=acceleration,
                            values=values, wide_gap=wide_gap(peak_y, peak),
                            settings=Settings(samples=samples, tolerance=tolerance, max_cycles=cycles,
                                              newton_iterations=newton))
    check_with_fmu(model, instance, [{**checked, "d": spec.wide_gap} if damper == "without" else checked
                                     for damper in DAMPER_CASES], "frequency response")
    return spec
