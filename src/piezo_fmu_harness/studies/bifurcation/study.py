"""The bifurcation diagram: at each frequency, after the transients, the Poincare
(stroboscopic) samples of the main mass's displacement ``p`` and the impacts per cycle, swept up and
down in frequency with the damper.

Each frequency starts from where the previous one's motion goes, as the frequency response's sweeps
do, and is marched on the batch engine (``piezo_fmu.solver.batch``) until its own trajectory shows
what it reaches (the rule of ``piezo_fmu.solver.batch.attractors.settle``): a stable orbit of order ``n``
gives its ``n`` section samples, the motion without impacts its one; a motion that reaches no
orbit within the budget ``--max-cycles`` gives the samples of its measuring window (its last
:data:`SAMPLES` periods) and its class. The two sweeps are two chains of tasks of the sweep
engine, a frequency a task, side by side (a progress bar follows them).

**Chaotic only when it persists**. One trajectory that has not reached an orbit when
the budget runs out may be on a long chaotic transient. So each such point is marched again with a
cloud of :data:`CLOUD` companions, its start with the velocities moved by ``1e-6`` of their size
(random, seeded): a transient lets them escape at its rate, an attractor keeps them. The cloud is
as large as the rule of :mod:`piezo_fmu_harness.starts.transients` needs to show, from one budget
with none escaping, that the motion would outlive a march as long again but for odds of 1 in 20.
The chain goes on from the point's own trajectory, so the clouds are tasks of their own, run beside
the chains on every worker. The point's motion is its own trajectory's: **periodic** once it
reaches an orbit (``periods`` says how long it took: the transient's length); else its cloud's
survival curve, the point's own trajectory among it, is fitted and the point is **chaotic** only
when the cloud persists and its own exponent's 95% interval lies above 0, **quasi-periodic** when
it persists with an exponent near 0 and a line spectrum, and **undecided** otherwise (``undecided
(converging)`` when its exponent lies below 0), with the cloud's mean transient lifetime where it
has one.

**The FMU checks the answer**: from the start of a sample of points (one of each class and each
orbit's order and impacts, the soonest, and ``--confirm`` more: :mod:`.chains`), the FMU is marched
and must reach the motion the diagram gives (:mod:`piezo_fmu_harness.starts.destination`);
``summary.json`` lists each check. The sweeps are recorded as they go (:mod:`.chains`, ``--resume``).

Files: ``bifurcation.nc`` (dims direction x omega x sample; the periods each point took and its
cloud's lifetime), ``bifurcation.csv`` (a row a sample), ``points.json`` (the damper's values and each sweep's points: the
start, the motion, the exponent's interval, the cloud's survival fit, the start-periods of each),
``summary.json`` (the budget, the times of the marching and of the checks, the start-periods of the
sweeps and of the clouds and the CPU seconds, the classes and where, the checks), ``bifurcation.png``;
``bifurcation.json`` and ``points.jsonl`` (:mod:`.chains`).

This study reads the simulation core's batch engine besides the FMU, which checks it: the one
exception, with the basins and the fractions, to the harness's rule that it reads nothing but the FMU.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ...datasets import bands
from ...periodic.band import FrequencySpec
from ...starts.transients import NONE_SEEN, ONSET, REACH
from ...store import write_json

DIRECTIONS = ("up", "down")
#: The files a diagram writes besides its header and ``points.jsonl`` (:mod:`.chains`).
FILES = ("bifurcation.nc", "bifurcation.csv", "points.json", "summary.json", "bifurcation.png")
#: The diagram's defaults: 200 frequencies over 0.5 to 2 sqrt(K/M), a budget of 1000 periods each.
DEFAULTS = {"ratios": (0.5, 2.0), "count": 200, "max_cycles": 1000, "fewest": 2}
#: The classes of motion, in the order the summary lists them.
CLASSES = ("periodic", "quasi-periodic", "chaotic", "undecided", "undecided (converging)", "error")
#: Companions of each point's trajectory: the fewest trajectories whose march of a budget, none
#: escaping, shows that the motion persists (a mean lifetime of ``REACH`` budgets at least, at 95%:
#: 76 of them), and 4 to spare for members set aside.
CLOUD = math.ceil(NONE_SEEN * REACH / (1.0 - ONSET)) + 3
#: How far the companions' velocities are moved, of their size.
NUDGE = 1e-6
#: Section samples of a point on no orbit kept for the diagram (the last of its measuring window).
SAMPLES = 40
#: Periods between two looks at a sweep's trajectory.
BLOCK = 20
#: Points the FMU checks besides one of each kind of motion (docs/harness.md: the checking then takes no
#: longer than the marching).
DEFAULT_CONFIRM = 2


def cloud(state, omega: float, amplitude: float, seed: int) -> np.ndarray:
    """:data:`CLOUD` companions of the start ``state``, their velocities moved by :data:`NUDGE` of
    the velocities' size (at least ``Y w``; the impact mass stays where it is relative to the
    barriers)."""
    state = np.asarray(state, float)
    size = max(float(np.abs(state[[1, 3]]).max()), amplitude * omega)
    kicks = np.random.default_rng(seed).standard_normal((CLOUD, 2)) * NUDGE * size
    others = np.repeat(state[None], CLOUD, axis=0)
    others[:, [1, 3]] += kicks
    return others


def frequency(instance, spec: dict, direction: str, number: int, state: list, side: float) -> dict:
    """Frequency ``number`` of one sweep (a task): its own trajectory marched alone on the batch
    engine from ``state`` (on ``side``), where the previous frequency's motion went; returns its
    point (with its section samples of ``p``, m), its trajectory's record and where its motion goes:
    the next frequency's start (:func:`follow`). A trajectory on no orbit at the budget waits for its
    cloud (:func:`companions`) before its motion is known."""
    from piezo_fmu.solver.batch import describe, settle

    ratio, omega, amplitude, params, drive, settings = _drive(spec, direction, number)
    begin = time.process_time()
    settled = settle(params, drive, [state], settings=settings, device=spec["device"], sides=[side])
    label = int(settled.labels[0])
    point = {"ratio": ratio, "omega": omega, "amplitude_Y": amplitude, "start": list(state),
             "start_side": side, "periods": int(settled.periods[0]), "status": "ok", "lifetime": None,
             "persists": None}
    record = None
    if label >= 0:
        attractor = describe(settled.attractors[label])
        point.update(motion="periodic", attractor=attractor, samples=[row[0] for row in attractor["sections"]],
                     impacts_per_cycle=attractor["impacts_per_cycle"], order=attractor["order"],
                     amplitude=attractor["amplitude"], lyapunov_exponent=None)
    elif label == -1:
        m = {name: float(values[0]) for name, values in settled.measures.items()}
        record = settled.records()[0][0]
        point.update(motion=None, attractor=None, samples=settled.samples[0][-SAMPLES:].tolist(),
                     impacts_per_cycle=m["impacts_per_cycle"], order=None, amplitude=m["amplitude"],
                     lyapunov_exponent=m["exponent"], exponent_low=m["exponent_low"], exponent_high=m["exponent_high"])
    else:
        point.update(status="error", motion="error", attractor=None, samples=[], impacts_per_cycle=None,
                     order=None, amplitude=None, lyapunov_exponent=None)
    point["cpu_seconds"] = time.process_time() - begin
    point["start_periods"] = int(settled.cycles)
    if label != -2:
        state, side = [float(v) for v in settled.final[0]], float(settled.final_sides[0])
    return {"point": point, "record": record, "next": (state, side)}


def companions(instance, spec: dict, direction: str, number: int, state: list, side: float) -> dict:
    """The cloud of frequency ``number``'s point (a task): its :data:`CLOUD` companions marched
    from around the point's start to where each goes, within the budget; returns their records
    (``label``, ``periods``) and the CPU time."""
    from piezo_fmu.solver.batch import settle

    _, omega, amplitude, params, drive, settings = _drive(spec, direction, number)
    begin = time.process_time()
    starts = cloud(state, omega, amplitude, number)
    settled = settle(params, drive, starts, settings=settings, device=spec["device"],
                     sides=[side] * len(starts), measured=False)
    records = [{"label": int(label), "periods": int(periods)}
               for label, periods in zip(settled.labels.tolist(), settled.periods.tolist())]
    return {"records": records, "cpu_seconds": time.process_time() - begin, "start_periods": int(settled.cycles)}


def _drive(spec: dict, direction: str, number: int):
    """Frequency ``number`` of the sweep ``direction``: its ratio to ``sqrt(K/M)``, ``omega``
    (rad/s), ``Y`` (m), the damper, its drive and the march's settings."""
    from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, damper

    ratios = spec["ratios"] if direction == "up" else spec["ratios"][::-1]
    ratio = ratios[number]
    omega = ratio * spec["natural"]
    amplitude = spec["amplitude"] if spec["amplitude"] is not None else spec["acceleration"] / omega**2
    settings = SettleSettings(tolerance=spec["settings"]["tolerance"], max_cycles=spec["settings"]["max_cycles"],
                              block=BLOCK)
    drive = HarmonicHold(omega, amplitude, 0.0, spec["settings"]["samples"])
    return ratio, omega, amplitude, damper(spec["values"]), drive, settings


def judged(point: dict, record: dict, clouded: dict) -> dict:
    """The point whose own trajectory reached no orbit, with its motion (the rule of the module's
    text): its cloud's survival fit, with the point's own record among the cloud's."""
    from ...starts.attractors import survival_fit, verdict
    from ...starts.transients import counts

    fit = survival_fit([record] + clouded["records"])
    motion = verdict(record, fit)
    return {**point, "motion": motion, "attractor": {"kind": motion if motion in ("chaotic", "quasi-periodic")
                                                     else "undecided"},
            "transients": counts(fit) if fit else None, "lifetime": fit.lifetime if fit else None,
            "persists": bool(fit.persists) if fit else None,
            "cpu_seconds": point["cpu_seconds"] + clouded["cpu_seconds"], "cloud_start_periods": clouded["start_periods"]}


def follow(spec: dict):
    """The chains of the two sweeps: each frequency's task, once done, calls for the next one's,
    from where its motion went, and for its cloud when its trajectory reached no orbit."""
    def next_tasks(tag, result):
        direction, number = tag[:2]
        if len(tag) == 3:  # a cloud
            return []
        more = []
        if number + 1 < len(spec["ratios"]):
            state, side = result["next"]
            more.append(((direction, number + 1), frequency, (spec, direction, number + 1, state, side)))
        if result["record"] is not None:
            point = result["point"]
            more.append(((direction, number, "cloud"), companions,
                         (spec, direction, number, point["start"], point["start_side"])))
        return more
    return next_tasks


def build_dataset(spec: FrequencySpec, sweeps: list[dict]):
    import xarray as xr

    count = len(spec.ratios)
    width = max(1, max(len(p["samples"]) for s in sweeps for p in s["points"]))
    samples = np.full((2, count, width), np.nan)
    impacts, exponent = np.full((2, count), np.nan), np.full((2, count), np.nan)
    periods, lifetime = np.full((2, count), np.nan), np.full((2, count), np.nan)
    motion = np.full((2, count), "missing", dtype=object)
    for j, result in enumerate(sweeps):
        for point in result["points"]:
            k = int(np.argmin(np.abs(np.array(spec.ratios) - point["ratio"])))
            samples[j, k, :len(point["samples"])] = point["samples"]
            impacts[j, k] = np.nan if point["impacts_per_cycle"] is None else point["impacts_per_cycle"]
            exponent[j, k] = np.nan if point["lyapunov_exponent"] is None else point["lyapunov_exponent"]
            motion[j, k] = point["motion"]
            periods[j, k] = point["periods"]
            lifetime[j, k] = np.nan if point.get("lifetime") is None else point["lifetime"]
    dims = ("direction", "omega")
    return xr.Dataset(
        {"p_section": (dims + ("sample",), samples, {"units": "m", "long_name": "Poincare samples of p at the section "
                                                                              "phase, after the transients"}),
         "impacts_per_cycle": (dims, impacts, {"units": "1", "long_name": "impacts per forcing cycle"}),
         "lyapunov_exponent": (dims, exponent, {"units": "1/period", "long_name": "largest Lyapunov exponent (motions "
                                                                                  "that are not periodic)"}),
         "motion": (dims, motion.astype(str), {"long_name": "periodic, quasi-periodic, chaotic (both shown to "
                                                            "persist), undecided, undecided (converging) or error"}),
         "periods": (dims, periods, {"units": "periods", "long_name": "periods the point's trajectory took to reach "
                                                                      "its orbit (the budget when it did not)"}),
         "lifetime": (dims, lifetime, {"units": "periods", "long_name": "mean transient lifetime of the point's "
                                                                        "cloud, where it was on no orbit"})},
        coords={"direction": list(DIRECTIONS),
                "omega": ("omega", spec.omegas, {"units": "rad/s", "long_name": "forcing frequency"}),
                "ratio": ("omega", np.array(spec.ratios), {"units": "1", "long_name": "w / sqrt(K/M)"})},
        attrs={"title": "piezo-impact damper: bifurcation diagram under harmonic base motion",
               "budget_periods": spec.settings.max_cycles, "cloud": CLOUD,
               "parameters": json.dumps(spec.values), "settings": json.dumps(asdict(spec.settings))})


def summarize(ds, times: dict, checked: list[dict], sweeps: list[dict]) -> dict:
    """The summary: the times (``wall_s`` in all, ``marching_s`` of the sweeps and their clouds,
    ``checking_s`` of the FMU's checks) and the work (start-periods marched by the sweeps' own
    trajectories and by the clouds, with Newton's and the measures'; the CPU seconds of the points),
    the classes and their bands, the FMU's checks."""
    from ...starts.fmu_checks import tally

    ratios = ds["ratio"].values
    points = [p for s in sweeps for p in s["points"]]
    undecided = np.char.startswith(ds["motion"].values.astype(str), "undecided")
    report = {**times, "cpu_s": sum(p["cpu_seconds"] for p in points),
              "start_periods": {"sweeps": sum(p["start_periods"] for p in points),
                                "clouds": sum(p.get("cloud_start_periods", 0) for p in points)},
              "points": int(ds["motion"].size), "budget_periods": int(ds.attrs["budget_periods"]),
              "undecided": int(undecided.sum()), "classes": {},
              "fmu_checks": {**tally(checked, times["checking_s"]), "points": checked}}
    for j, direction in enumerate(DIRECTIONS):
        motion = ds["motion"].values[j]
        report["classes"][direction] = {kind: {"count": int((motion == kind).sum()), "bands": bands(ratios, motion == kind)}
                                        for kind in CLASSES if (motion == kind).any()}
    return report


def write(spec: FrequencySpec, sweeps: list[dict], folder: Path, times: dict, checked: list[dict], begin: float) -> dict:
    """Write the diagram's files (:data:`FILES`); ``times``: ``marching_s`` and ``checking_s``;
    ``begin``: when the command's work began (``time.perf_counter``), for ``wall_s``."""
    from ...datasets import csv_frame, save_dataset, units_of
    from .figure import draw

    ds = build_dataset(spec, sweeps)
    draw(ds, folder / "bifurcation.png")
    save_dataset(ds, folder / "bifurcation.nc")
    frame = ds[["p_section"]].to_dataframe().dropna().reset_index()
    frame = frame.merge(ds[["impacts_per_cycle", "motion"]].to_dataframe().reset_index(),  # ratio is omega's: one
                        on=["direction", "omega", "ratio"])
    csv_frame(frame, units_of(ds)).to_csv(folder / "bifurcation.csv", index=False)
    (folder / "points.json").write_text(json.dumps({"values": spec.values, "sweeps": sweeps}) + "\n")
    report = summarize(ds, {"wall_s": time.perf_counter() - begin, **times}, checked, sweeps)
    write_json(folder / "summary.json", report)
    return report
