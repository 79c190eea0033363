"""The bifurcation diagram (issue 23): at each frequency, after the transients, the Poincare
(stroboscopic) samples of the main mass's displacement ``p`` and the impacts per cycle, swept up and
down in frequency with the damper.

Each frequency starts from the previous one's final state, as the frequency response's sweeps do,
and its steady state is found the same way (:mod:`piezo_fmu_harness.periodic.steady_state`): a
stable orbit of order ``n`` gives its ``n`` section samples; a motion that is not periodic gives
the samples of its classification window (40 periods) and its class: quasi-periodic, strongly
modulated, chaotic, or a transient still converging
(:mod:`piezo_fmu_harness.periodic.motion`). The two sweeps are two tasks of the sweep engine.

Files: ``bifurcation.nc`` (dims direction x omega x sample), ``bifurcation.csv`` (a row a sample),
``summary.json`` (the classes and where), ``bifurcation.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ...datasets import bands
from ...periodic.band import FrequencySpec, solve_chain
from ...periodic.steady_state import Settings

DIRECTIONS = ("up", "down")
#: The diagram's defaults: 200 frequencies over 0.5 to 2 sqrt(K/M), at most 200 cycles each.
DEFAULTS = {"ratios": (0.5, 2.0), "count": 200, "max_cycles": 200, "fewest": 2}
#: The classes of motion, in the order the summary lists them.
CLASSES = ("periodic", "quasi-periodic", "strongly modulated", "chaotic", "transient", "unclassified", "error")


def sweep(instance, spec: dict, direction: str) -> dict:
    """One sweep of the diagram (a task): each frequency's steady state from the previous state,
    with its section samples of ``p`` (m)."""
    ratios = spec["ratios"] if direction == "up" else spec["ratios"][::-1]
    omegas = [ratio * spec["natural"] for ratio in ratios]
    records = solve_chain(instance, [(spec["values"], omega, spec["amplitude"] if spec["amplitude"] is not None
                                      else spec["acceleration"] / omega**2) for omega in omegas],
                          Settings(**spec["settings"]))
    points = []
    for ratio, record in zip(ratios, records):
        points.append({"ratio": ratio, "status": record.get("status"), "motion": record.get("motion", "error"),
                       "samples": [s[0] for s in record.get("sections") or []],
                       "impacts_per_cycle": record.get("impacts_per_cycle"), "order": record.get("order"),
                       "lyapunov_exponent": record.get("lyapunov_exponent"), "amplitude": record.get("amplitude"),
                       "cpu_seconds": record.get("cpu_seconds")})
    return {"direction": direction, "points": points}


def run(spec: FrequencySpec, backend) -> tuple[list[dict], float]:
    """Both sweeps on ``backend``; returns them (up first) and the wall time (s)."""
    begin = time.perf_counter()
    plain = {"values": spec.values, "settings": asdict(spec.settings), "ratios": list(spec.ratios),
             "natural": spec.natural, "amplitude": spec.amplitude, "acceleration": spec.acceleration}
    results = [result for _, result in backend.run_tasks([(d, sweep, (plain, d)) for d in DIRECTIONS])]
    results.sort(key=lambda r: DIRECTIONS.index(r["direction"]))
    return results, time.perf_counter() - begin


def build_dataset(spec: FrequencySpec, sweeps: list[dict]):
    import xarray as xr

    count = len(spec.ratios)
    width = max(1, max(len(p["samples"]) for s in sweeps for p in s["points"]))
    samples = np.full((2, count, width), np.nan)
    impacts, exponent = np.full((2, count), np.nan), np.full((2, count), np.nan)
    motion = np.full((2, count), "missing", dtype=object)
    for j, result in enumerate(sweeps):
        for point in result["points"]:
            k = int(np.argmin(np.abs(np.array(spec.ratios) - point["ratio"])))
            samples[j, k, :len(point["samples"])] = point["samples"]
            impacts[j, k] = np.nan if point["impacts_per_cycle"] is None else point["impacts_per_cycle"]
            exponent[j, k] = np.nan if point["lyapunov_exponent"] is None else point["lyapunov_exponent"]
            motion[j, k] = point["motion"]
    dims = ("direction", "omega")
    return xr.Dataset(
        {"p_section": (dims + ("sample",), samples, {"units": "m", "long_name": "Poincare samples of p at the section "
                                                                              "phase, after the transients"}),
         "impacts_per_cycle": (dims, impacts, {"units": "1", "long_name": "impacts per forcing cycle"}),
         "lyapunov_exponent": (dims, exponent, {"units": "1/period", "long_name": "largest Lyapunov exponent (motions "
                                                                                  "that are not periodic)"}),
         "motion": (dims, motion.astype(str), {"long_name": "periodic, quasi-periodic, strongly modulated, chaotic, "
                                                            "transient, unclassified or error"})},
        coords={"direction": list(DIRECTIONS), "omega": spec.omegas,
                "ratio": ("omega", np.array(spec.ratios), {"units": "1", "long_name": "w / sqrt(K/M)"})},
        attrs={"title": "piezo-impact damper: bifurcation diagram under harmonic base motion",
               "parameters": json.dumps(spec.values), "settings": json.dumps(asdict(spec.settings))})


def summarize(ds, wall: float) -> dict:
    ratios = ds["ratio"].values
    report = {"wall_s": wall, "points": int(ds["motion"].size), "classes": {}}
    for j, direction in enumerate(DIRECTIONS):
        motion = ds["motion"].values[j]
        report["classes"][direction] = {kind: {"count": int((motion == kind).sum()), "bands": bands(ratios, motion == kind)}
                                        for kind in CLASSES if (motion == kind).any()}
    return report


def write(spec: FrequencySpec, sweeps: list[dict], folder: Path, wall: float) -> dict:
    from ...datasets import save_dataset
    from .figure import draw

    ds = build_dataset(spec, sweeps)
    save_dataset(ds, folder / "bifurcation.nc")
    frame = ds[["p_section"]].to_dataframe().dropna().reset_index()
    frame.merge(ds[["impacts_per_cycle", "motion"]].to_dataframe().reset_index(),
                on=["direction", "omega"]).to_csv(folder / "bifurcation.csv", index=False)
    report = summarize(ds, wall)
    (folder / "summary.json").write_text(json.dumps(report, indent=2) + "\n")
    draw(ds, folder / "bifurcation.png")
    return report
