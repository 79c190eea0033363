"""``piezo-fmu optimize``: a design optimiser over FMU parameters, through the FMU (or, under a
spectrum, the batch engine).

``scipy.optimize.differential_evolution`` searches chosen parameters within bounds. Its
``workers`` map is the sweep engine (process pool, Dask or in-process), so a generation's
evaluations run in parallel; the final polish (Nelder-Mead, ``--polish``) goes through the same map. The objective
``J`` is minimised; it is a weighted sum of dimensionless terms, each normalised by a stated
reference value, the reference design's own (the FMU's start values and ``--set``, the nominal
damper) unless given:

- ``perfectibility`` (free decay, the paper's): terms ``DI`` (eq. 29, or ``DI_ls`` with
  ``--damping ls``) and ``V_rms``, both to be large, over ``stop_time`` from the nominal release.
  ``J = -100 (w_DI DI / DI_ref + w_V V_rms / V_ref)``: with the default weights 0.5 and 0.5,
  ``-J`` is eq. 31's perfectibility with the maxima replaced by the reference values.
- ``forced`` (harmonic base motion over a band, :mod:`piezo_fmu_harness.studies.forced.chains`; one sweep up
  with the damper): terms ``amplitude``, the peak steady-state amplitude over the band with the
  damper over the same peak without it (to be small), ``transmissibility``, the peak amplitude over
  ``Y`` (to be small), and ``power``, the mean harvested power over the band over the reference
  design's (to be large), and ``worst`` (weight 0 unless given), the larger of the peaks of a sweep
  up and a sweep down over the peak without the damper: the worst stable response a machine may
  show, whichever way it came. ``J = w_a amplitude + w_t transmissibility - w_p power + w_w worst``. The response
  at each frequency is the stable one: a stable orbit or, where none is found, the motion that is
  not periodic, measured over its window (its amplitude the envelope's top); an unstable orbit
  never scores.
- ``random`` (random base acceleration under a PSD, :mod:`.spectrum`; the realizations 0 to N-1
  of the same seed for every design, with and without the damper, on the batch engine): terms
  ``ratio``, the paired ratio of the RMS of the main mass's displacement relative to the base with
  the damper over without it (to be small), and ``power``, the mean power harvested in both loads
  over the reference design's (to be large; weight 0 unless given). ``J = w_r ratio - w_p power``.

A weight may be negative (it turns what its term rewards around) or zero (the term is not
computed when that saves work).

The report (:mod:`piezo_fmu_harness.studies.optimize.report`) gives the optimum, its sensitivity (one
parameter at a time, a step of a fraction of its range each way) and the best point of a
full-factorial grid of the same budget (as many evaluations as the optimiser needed), so a user
sees whether the optimiser earned its cost.

Every evaluation is appended to ``evaluations.jsonl`` as it finishes. ``--resume`` reads them back
as a cache: the same seed makes the optimiser propose the same points again, each found in the
cache, so an interrupted run goes on where it stopped and loses nothing.

The harness reads nothing but the FMU for the perfectibility and the forced response; under
``random`` it marches on the simulation core's batch engine (:mod:`.spectrum`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ...fmu import FmuRunError, Instance
from ...periodic.band import FrequencySpec
from .band import sweep_band
from ...store import PointStore
from .log import EVALUATIONS_FILE

#: The files an optimisation writes besides its header and ``evaluations.jsonl``.
FILES = ("report.md", "report.json", "evaluations.csv", "convergence.png")
#: Each objective's terms: +1 for a term to be large (it enters J with a minus sign), -1 small.
TERMS = {
    "perfectibility": {"DI": 1, "V_rms": 1},
    "forced": {"amplitude": -1, "transmissibility": -1, "power": 1, "worst": -1},
    "random": {"ratio": -1, "power": 1},
}
DEFAULT_WEIGHTS = {
    "perfectibility": {"DI": 0.5, "V_rms": 0.5},
    # Lightly on power: the regimes that harvest most chatter with large amplitude (with 0.5, the
    # optimum of (m, d) was such a regime, its peak 119 mm against 16 mm for the best amplitude).
    "forced": {"amplitude": 1.0, "transmissibility": 0.0, "power": 0.1, "worst": 0.0},
    # The ratio alone: J is what a user of the random study reads, and the power, which follows
    # the impacts, is reported (a weight trades it against the ratio).
    "random": {"ratio": 1.0, "power": 0.0},
}
#: The perfectibility's terms are in % (eq. 31).
SCALE = {"perfectibility": 100.0, "forced": 1.0, "random": 1.0}
#: The reference values a user may state (SI), by objective.
REFERENCES = {"perfectibility": ("DI", "V_rms"), "forced": ("power", "amplitude_without"), "random": ("power",)}
#: The search's defaults, by objective: a forced evaluation sweeps a band, a free decay is one run.
SEARCH_DEFAULTS = {
    "perfectibility": {"maxiter": 30, "popsize": 15, "tol": 0.01, "sensitivity_step": 0.02},
    "forced": {"maxiter": 8, "popsize": 6, "tol": 0.01, "sensitivity_step": 0.02},
    "random": {"maxiter": 8, "popsize": 6, "tol": 0.01, "sensitivity_step": 0.02},
}
#: The forced objective's band: w / sqrt(K/M) from 0.8 to 1.2 at 9 frequencies, at most 150 cycles
#: each (every evaluation sweeps it); a single frequency is allowed.
BAND_DEFAULTS = {"ratios": (0.8, 1.2), "count": 9, "max_cycles": 150, "fewest": 1}
#: Parameters the forced and random objectives cannot search: the initial state (the shooting sets
#: it; every realization starts from rest).
STATE = ("p0", "q0", "dp0", "dq0")


@dataclass(frozen=True)
class Problem:
    """What is optimised (SI).

    Attributes
    ----------
    names, lower, upper : tuple
        The searched parameters and their bounds.
    objective : str
        ``perfectibility``, ``forced`` or ``random``.
    weights : dict
        Weight of each term of the objective.
    fixed : dict
        FMU parameters held fixed (``--set``, and under ``forced`` and ``random`` the voltage model
        and load; under ``random`` every parameter, from rest).
    stop_time, step : float
        Duration and communication step of a free-decay run (``perfectibility``), s.
    damping : str
        ``DI`` (eq. 29) or ``DI_ls``: the damping term of ``perfectibility``.
    band : FrequencySpec or None
        The frequencies, excitation and steady-state settings of ``forced``.
    without_each_time : bool
        Under ``forced``: the peak without the damper changes with the searched parameters
        (``M``, ``K`` or ``C`` among them), so each evaluation computes it.
    random : dict or None
        Under ``random``: the excitation, realizations and window
        (:class:`~piezo_fmu_harness.random_response.spec.RandomSpec`, as a dict), whose ``values``
        each design's replace.
    """

    names: tuple
    lower: tuple
    upper: tuple
    objective: str
    weights: dict
    fixed: dict
    stop_time: float = 2.0
    step: float = 0.2
    damping: str = "DI"
    band: Optional[FrequencySpec] = None
    without_each_time: bool = False
    random: Optional[dict] = None

    def values(self, x) -> dict:
        return {**self.fixed, **{name: float(v) for name, v in zip(self.names, x)}}

    def to_dict(self) -> dict:
        body = asdict(self)
        body["band"] = self.band.to_dict() if self.band is not None else None
        return body


# -- one evaluation, in a worker -------------------------------------------------------------------

def evaluate(instance: Instance, problem: Problem, x, without: bool = False) -> dict:
    """The raw measures of the design ``x`` (a task of the sweep engine): under
    ``perfectibility`` the free-decay metrics; under ``forced`` the peak amplitude and
    transmissibility over the band, the mean harvested power and how many frequencies did not
    settle, with the peak without the damper when ``without`` (or the problem says so); under
    ``random`` the RMS ratio and the power over the realizations (:func:`.spectrum.march_design`)."""
    begin = time.perf_counter()
    values = problem.values(x)
    record = {"x": [float(v) for v in x], "status": "ok", "error": None}
    try:
        if problem.objective == "perfectibility":
            metrics = instance.run(values, problem.stop_time, problem.step)
            record["measures"] = {key: metrics.get(key) for key in ("DI", "DI_ls", "V_rms", "impact_count")}
        elif problem.objective == "random":
            from .spectrum import march_design

            record["measures"] = march_design(problem.random, values)
        else:
            record["measures"] = sweep_band(instance, problem.band, values, with_damper=True)
            if problem.weights.get("worst"):  # the sweep down too: the worse of the two stable responses
                record["measures"]["amplitude_down"] = sweep_band(instance, problem.band, values, True, "down")["amplitude"]
            if without or problem.without_each_time:
                bare = sweep_band(instance, problem.band, {**values, "d": problem.band.wide_gap}, with_damper=False)
                record["measures"]["amplitude_without"] = bare["amplitude"]
    except FmuRunError as error:
        record.update(status="error", error=str(error), measures={})
    record["seconds"] = time.perf_counter() - begin
    return record


# -- the objective ---------------------------------------------------------------------------------

def terms(problem: Problem, measures: dict, references: dict) -> dict:
    """The dimensionless terms of a design from its raw measures."""
    if problem.objective == "perfectibility":
        return {"DI": measures[problem.damping] / references["DI"], "V_rms": measures["V_rms"] / references["V_rms"]}
    power = measures["power"] / references["power"] if references.get("power") else math.nan
    if problem.objective == "random":
        return {"ratio": measures["ratio"], "power": power}
    without = measures.get("amplitude_without", references.get("amplitude_without"))
    return {"amplitude": measures["amplitude"] / without if without else math.nan,
            "transmissibility": measures["transmissibility"],
            "power": power,
            "worst": (max(measures["amplitude"], measures["amplitude_down"]) / without
                      if without and measures.get("amplitude_down") is not None else math.nan)}


def objective_value(problem: Problem, parts: dict) -> float:
    """``J``: the weighted terms, large-is-better ones with a minus sign (see the module)."""
    sense = TERMS[problem.objective]
    total = sum(-sense[name] * weight * parts[name] for name, weight in problem.weights.items() if weight != 0)
    return SCALE[problem.objective] * total


# -- the optimiser ---------------------------------------------------------------------------------

@dataclass
class Optimizer:
    """Runs the search, the grid and the sensitivity on ``backend``, logging every evaluation.

    ``references`` are filled by :meth:`reference` unless given; ``cache`` holds the evaluations
    already made (from ``evaluations.jsonl`` on ``--resume``), by their parameter values."""

    problem: Problem
    backend: object
    folder: Path
    references: dict = field(default_factory=dict)
    cache: dict = field(default_factory=dict)
    phase: str = "search"
    #: counts the evaluations as they finish (a tqdm bar), or None
    bar: object = None

    def __post_init__(self) -> None:
        # the next evaluation's index: after those recorded (a line deleted from the log leaves a gap)
        self._next = max((record["index"] for record in self.cache.values()), default=-1) + 1

    def _key(self, x) -> tuple:
        return (self.phase if self.phase == "reference" else "design",) + tuple(repr(float(v)) for v in x)

    def records(self, xs, without: bool = False) -> list[dict]:
        """The evaluation records of the designs ``xs``: from the cache, or run on the backend
        (in parallel, each distinct design once) and appended to ``evaluations.jsonl`` as each
        finishes."""
        xs = [np.asarray(x, float) for x in xs]
        # Each design once: a population may hold the same design twice.
        missing = list({self._key(x): x for x in xs if self._key(x) not in self.cache}.values())
        if missing:
            tasks = [(k, _evaluate_task, ((self.problem, x, without),)) for k, x in enumerate(missing)]
            with PointStore(self.folder, EVALUATIONS_FILE) as store:
                for _, record in self.backend.run_tasks(tasks):
                    record["phase"] = self.phase
                    record["index"], self._next = self._next, self._next + 1
                    self._score(record)
                    self.cache[self._key(record["x"])] = record
                    store.append(record)
                    if self.bar is not None:
                        self.bar.update(1)
        return [self.cache[self._key(x)] for x in xs]

    def _score(self, record: dict) -> None:
        if record["status"] != "ok" or not self.references:
            record.update(terms=None, objective=None)
            return
        parts = terms(self.problem, record["measures"], self.references)
        value = objective_value(self.problem, parts)
        # JSON has no NaN: a term without a reference (weight 0) is recorded as null.
        record.update(terms={k: (v if math.isfinite(v) else None) for k, v in parts.items()},
                      objective=value if math.isfinite(value) else None)

    def map(self, func, xs) -> list[float]:
        """``differential_evolution``'s ``workers``: J of every design in ``xs``. ``func`` is this
        optimiser's :meth:`objective` (the search's own objective), evaluated here on the backend."""
        return [value(record) for record in self.records(list(xs))]

    def objective(self, x) -> float:
        return value(self.records([x])[0])

    def reference(self, x_reference) -> dict:
        """Measure the reference design: the denominators of the terms (unless given)."""
        self.phase = "reference"
        record = self.records([x_reference], without=self.problem.objective == "forced")[0]
        self.phase = "search"
        if record["status"] != "ok":
            raise FmuRunError(f"the reference design was rejected: {record['error']}")
        measures = record["measures"]
        if self.problem.objective == "perfectibility":
            found = {"DI": measures[self.problem.damping], "V_rms": measures["V_rms"]}
        elif self.problem.objective == "random":
            found = {"power": measures["power"]}
        else:
            found = {"power": measures["power"], "amplitude_without": measures["amplitude_without"]}
        self.references = {**found, **self.references}
        for name, weight in self.problem.weights.items():
            if weight != 0 and name in self.references and not self.references[name] > 0:
                raise ValueError(f"the reference design's {name} is {self.references[name]:g}, which cannot "
                                 f"normalise the term {name}: give --reference {name}=VALUE (> 0) or --weight "
                                 f"{name}=0")
        for cached in self.cache.values():
            self._score(cached)
        return record

    def search(self, maxiter: int, popsize: int, seed: int, polish: bool, tol: float):
        from scipy.optimize import differential_evolution

        from .polish import polish_simplex

        self.phase = "search"
        bounds = list(zip(self.problem.lower, self.problem.upper))
        return differential_evolution(self.objective, bounds, maxiter=maxiter, popsize=popsize, tol=tol, rng=seed,
                                      polish=polish_simplex if polish else False, updating="deferred",
                                      workers=self.map, init="latinhypercube")

    def grid(self, budget: int) -> tuple[int, list[dict]]:
        """A full-factorial grid of at most ``budget`` points over the bounds (at least 2 per axis)."""
        self.phase = "grid"
        per_axis = max(2, int(math.floor(budget ** (1.0 / len(self.problem.names)) + 1e-9)))
        axes = [np.linspace(lo, hi, per_axis) for lo, hi in zip(self.problem.lower, self.problem.upper)]
        points = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T
        return per_axis, self.records(points)

    def sensitivity(self, x, fraction: float) -> list[dict]:
        """J one step of ``fraction`` of each range either side of ``x`` (clipped to the bounds)."""
        self.phase = "sensitivity"
        rows, designs = [], []
        for i, (lo, hi) in enumerate(zip(self.problem.lower, self.problem.upper)):
            step = fraction * (hi - lo)
            for sign in (-1.0, 1.0):
                shifted = np.array(x, float)
                shifted[i] = min(hi, max(lo, shifted[i] + sign * step))
                designs.append(shifted)
        records = self.records(designs)
        base = value(self.records([x])[0])
        for i, name in enumerate(self.problem.names):
            minus, plus = records[2 * i], records[2 * i + 1]
            span = plus["x"][i] - minus["x"][i]
            change = [value(r) - base for r in (minus, plus)]
            rows.append({"name": name, "at": float(x[i]), "minus": minus["x"][i], "plus": plus["x"][i],
                         "objective_minus": minus["objective"], "objective_plus": plus["objective"],
                         "change_minus": _finite(change[0]), "change_plus": _finite(change[1]),
                         "slope_per_range": _finite((value(plus) - value(minus)) / span
                                                    * (self.problem.upper[i] - self.problem.lower[i])) if span else None})
        return rows


def value(record: dict) -> float:
    """A record's J; +inf for a design the FMU rejected or whose J is undefined (null in the log)."""
    return math.inf if record["objective"] is None else record["objective"]


def _evaluate_task(instance: Instance, item: tuple) -> dict:
    problem, x, without = item
    return evaluate(instance, problem, x, without)


def run(optimizer: Optimizer, x_reference, maxiter: int, popsize: int, seed: int, polish: bool, tol: float,
        grid: bool, fraction: float) -> dict:
    """The whole optimisation: reference, search, grid of the same budget, sensitivity; returns
    the report (JSON-safe)."""
    problem = optimizer.problem
    begin = time.perf_counter()
    reference = optimizer.reference(x_reference)
    result = optimizer.search(maxiter, popsize, seed, polish, tol)
    search_s = time.perf_counter() - begin
    evaluations = int(result.nfev)
    best = optimizer.records([result.x])[0]
    report = {
        "objective": problem.objective,
        "weights": problem.weights,
        "references": optimizer.references,
        "reference_design": _design(problem, reference),
        "optimum": _design(problem, best),
        "search": {"evaluations": evaluations, "unique_evaluations": len({optimizer._key(r["x"]) for r in
                                                                         optimizer.cache.values()
                                                                         if r.get("phase") == "search"}),
                   "generations": int(result.nit), "message": str(result.message), "wall_s": search_s,
                   "maxiter": maxiter, "popsize": popsize, "seed": seed, "polish": polish, "tol": tol},
    }
    if problem.random:  # the excitation and the realizations every design was marched on
        report["excitation"] = {key: problem.random[key] for key in ("source", "levels", "realizations", "seed",
                                                                      "warmup", "duration", "step", "f_low")}
    if grid:
        per_axis, records = optimizer.grid(evaluations)
        finite = [r for r in records if r["objective"] is not None]
        top = min(finite, key=value) if finite else None
        report["grid"] = {"points_per_axis": per_axis, "evaluations": len(records),
                          "best": _design(problem, top) if top else None,
                          "optimizer_matches_or_beats_grid": bool(top is None or value(best) <= value(top))}
    report["sensitivity"] = {"fraction_of_range": fraction, "parameters": optimizer.sensitivity(result.x, fraction)}
    report["wall_s"] = time.perf_counter() - begin
    return report


def _finite(number: float) -> Optional[float]:
    return number if math.isfinite(number) else None


def _design(problem: Problem, record: dict) -> dict:
    return {"x": dict(zip(problem.names, record["x"])), "objective": record["objective"], "terms": record["terms"],
            "measures": record["measures"]}
