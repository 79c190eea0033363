"""One realization of a random-excitation study, step by step: its input as an FMI host replays it, the
batch engine's motion with and without the damper, and the same input marched through the FMU alone
(the study's independent check).

:func:`trace` marches realization ``r`` at level ``k`` on the batch engine one step a block (the
same bits as the study's march: a trajectory's bits do not depend on the blocks), keeping the main
mass's displacement and the impacts so far at every step's end. :func:`fmu_trace` feeds the FMU the
same input, ``base_displacement`` and ``base_velocity`` set at each step's start, as fmpy's
``simulate_fmu(..., input=...)`` does, and reads the same outputs.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ...random_response.spec import RandomSpec


def inputs(spec: RandomSpec, realization: int, level: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``steps`` nodes (``steps + 1``, m) and slopes (``steps``, m/s) of ``realization`` at
    ``level`` (the first level's scaled, as the study's march takes them)."""
    y, v = spec.excitation(0).stream(realization).take(steps)
    scale = math.sqrt(spec.levels[level] / spec.levels[0]) if spec.levels else 1.0
    return y * scale, v * scale


def trace(spec: RandomSpec, realization: int, level: int, steps: int, case: str = "with") -> dict:
    """The batch engine's ``p`` (m) and impacts so far at each of the first ``steps`` steps' ends
    of ``realization`` at ``level`` (``case`` "with" or "without" the damper), with the times (s)."""
    from piezo_fmu.solver.batch import damper
    from piezo_fmu.solver.batch.input_ensemble import InputEnsemble

    y, v = inputs(spec, realization, level, steps)
    ensemble = InputEnsemble(damper(spec.values if case == "with" else spec.without), spec.step, np.zeros((1, 4)),
                             device="cpu")
    positions, onsets = ensemble.advance(y[None], v[None], onsets=True)
    return {"time": spec.step * np.arange(1, steps + 1), "main_displacement": positions[0],
            "impact_count": np.cumsum(onsets[0]), "base_displacement": y[1:]}


def fmu_trace(instance, values: dict, y: np.ndarray, v: np.ndarray, step: float) -> dict:
    """The FMU's ``main_displacement`` (m) and ``impact_count`` at each step's end, fed the nodes
    ``y`` and slopes ``v`` (its parameters ``values``, the start at rest)."""
    model = instance.model
    refs = [model.inputs["base_displacement"], model.inputs["base_velocity"]]
    kind, p_ref = model.outputs["main_displacement"]
    _, count_ref = model.outputs["impact_count"]
    instance.start(values, {"base_displacement": float(y[0]), "base_velocity": float(v[0])})
    fmu = instance.fmu
    positions, impacts = np.empty(len(v)), np.empty(len(v), np.int64)
    t = 0.0
    for k in range(len(v)):
        fmu.setReal(refs, [float(y[k]), float(v[k])])
        end = (k + 1) * step
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=end - t)
        t = end
        positions[k] = fmu.getReal([p_ref])[0]
        impacts[k] = fmu.getInteger([count_ref])[0]
    return {"main_displacement": positions, "impact_count": impacts}


def check_task(instance, spec_dict: dict, realization: int, level: int) -> dict:
    """A task: realization ``realization`` at ``level``, with the damper, through the FMU and on the
    batch engine over the whole record: where the two parted (the first step more than
    :data:`PART` m apart), the largest difference over the first second, and each one's RMS of the
    relative displacement over the window and impacts in it (judged by :func:`verdict`)."""
    import time

    begin = time.perf_counter()
    spec = RandomSpec.from_dict(spec_dict)
    steps = spec.steps
    engine = trace(spec, realization, level, steps)
    y, v = inputs(spec, realization, level, steps)
    fmu = fmu_trace(instance, spec.values, y, v, spec.step)
    gap = np.abs(fmu["main_displacement"] - engine["main_displacement"])
    parted = np.flatnonzero(~(gap <= PART))
    first_second = min(steps, int(round(1.0 / spec.step)))
    window = slice(spec.warmup_steps, steps)

    def rms(p):
        return float(np.sqrt(np.mean((p[window] - y[1:][window]) ** 2)))

    def impacts(counts):
        return int(counts[-1] - (counts[spec.warmup_steps - 1] if spec.warmup_steps else 0))

    rms_fmu, rms_engine = rms(fmu["main_displacement"]), rms(engine["main_displacement"])
    impacts_fmu, impacts_engine = impacts(fmu["impact_count"]), impacts(engine["impact_count"])
    return {"realization": realization, "level": level,
            "largest_gap_first_second_m": float(gap[:first_second].max()),
            "parted_at_s": None if not len(parted) else float((parted[0] + 1) * spec.step),
            "rms_relative_fmu": rms_fmu, "rms_relative_engine": rms_engine,
            "impacts_fmu": impacts_fmu, "impacts_engine": impacts_engine,
            "seconds": time.perf_counter() - begin}


#: The FMU and the batch engine have parted where their main masses are farther apart (m).
PART = 1e-9
#: The two-sided level of the window's judgement: that of three standard deviations of a normal
#: variable (99.73%).
SPREADS = 3.0
#: The variance a count gets from being a whole number (Sheppard's correction, 1/12): the floor of the
#: impacts' scatter, which a few short realizations may otherwise estimate as 0 (all with 7 impacts).
COUNT_ROUNDING = 1.0 / 12.0


@functools.lru_cache(maxsize=None)
def spread_factor(count: int) -> float:
    """The multiple of a difference's estimated standard deviation within which it lies at the level
    of :data:`SPREADS` normal deviations, the deviation estimated from ``count`` realizations:
    Student's ``t`` with ``count - 1`` degrees of freedom (3.01 for 1,000; 236 for 2, where two
    values say almost nothing of the scatter)."""
    from scipy import stats

    return float(stats.t.ppf(stats.norm.cdf(SPREADS), count - 1))


def verdict(check: dict, spread: dict | None) -> dict:
    """``check`` (:func:`check_task`'s) with its verdict: it **agrees** when the FMU follows the batch
    engine within :data:`PART` over the first second and its RMS and impacts over the window differ
    from the engine's by no more than :func:`spread_factor` times ``sqrt(2)`` standard deviations
    of the realizations' own (the impacts' with :data:`COUNT_ROUNDING` added to their variance;
    ``spread``: ``rms_relative`` (m) and ``impacts``, at that level with
    the damper, and ``count``, the realizations they come from; None for a study of one
    realization, a record, whose window is then not judged). Once the two have parted (the impacts
    make the motion chaotic, and rounding decides an impact's timing), they are two trajectories of
    the same input, whose window measures differ as two realizations' do (a standard deviation of
    ``sqrt(2)`` theirs); an engine or an FMU that moved otherwise would part at once."""
    close = check["largest_gap_first_second_m"] <= PART
    if spread is None:
        return {**check, "agrees": bool(close), "tolerance_rms_relative_m": None, "tolerance_impacts": None}
    factor = spread_factor(spread["count"]) * math.sqrt(2.0)
    tolerance = {"rms_relative": factor * spread["rms_relative"],
                 "impacts": factor * math.hypot(spread["impacts"], math.sqrt(COUNT_ROUNDING))}
    same = abs(check["rms_relative_fmu"] - check["rms_relative_engine"]) <= tolerance["rms_relative"] and \
        abs(check["impacts_fmu"] - check["impacts_engine"]) <= tolerance["impacts"]
    return {**check, "agrees": bool(close and same), "tolerance_rms_relative_m": tolerance["rms_relative"],
            "tolerance_impacts": tolerance["impacts"]}
