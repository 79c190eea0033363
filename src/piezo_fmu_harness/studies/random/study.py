"""The damper under random base excitation: how much it takes away from the main mass's response under a
spectrum (or a recorded ground motion), with what confidence, and what it harvests.

``--realizations`` realizations of the base acceleration (:mod:`piezo_fmu_harness.excitation`) are
each marched with and without the damper on the same input, on the batch engine's compiled kernel
(:mod:`.march`), at every level; the warm-up is discarded and the window's measures kept per
realization. The realizations run in chunks, each a task of the sweep engine, appended to
``points.jsonl`` as they finish (``--resume`` runs the others). The estimates and their intervals
come from the realizations (:mod:`.results`, :mod:`.statistics`).

**The FMU checks the answer**: ``--confirm`` realizations, drawn with ``--seed``, are marched through
the FMU alone on their inputs (:mod:`.trace`): it must follow the batch engine to 1e-9 m over the
first second, and give the same RMS and impacts over the window within what chaos allows.

Files: ``random.nc`` (each realization's measures over ``level x realization x damper``, the
response PSD over ``level x damper x frequency``), ``random.csv`` (a row a level and a damper: the
estimates and their intervals), ``psd.csv`` (the response PSD with and without, and the linear
oscillator's), ``summary.json`` (the excitation and its PSD convention, every setting, the
estimates, the FMU's checks, the times), ``random.json`` (the run's header), figures
(``effectiveness.png``, ``psd.png``, ``history.png``, ``peaks.png``), and with ``--save-input K``
``input_K.csv`` and ``response_K.csv``.

This study reads the simulation core's batch engine (``piezo_fmu.solver.batch``) besides the FMU,
which checks it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...store import Damaged, open_folder, require, within
from ...random_response.march import DAMPERS, march_chunk
from ...store import write_json
from .results import MEASURES, arrays, psd, summarize
from ...random_response.spec import RandomSpec

HEADER_FILE = "random.json"
#: The FMU's checks by default: realizations marched through it.
DEFAULT_CONFIRM = 1


def open_random(model, spec: RandomSpec, folder: Path, resume: bool, force: bool):
    header = {**spec.to_dict(), "fmu_guid": model.guid}
    same = tuple(k for k in header if k not in ("confirm", "save_input"))
    return open_folder(folder, HEADER_FILE, header, same, resume, force, "--out", "random-excitation study",
                       check=record_check(spec))


def record_check(spec: RandomSpec):
    """The check of a recorded chunk: one of the study's chunks, with a record for each of its
    realizations at every level (:func:`piezo_fmu_harness.store.open_folder`)."""
    layout = spec.chunks()
    levels = max(len(spec.levels), 1)

    def check(record: dict) -> None:
        within(record["index"], len(layout), "chunk")
        require(record, {"realizations": list, "psd": dict})
        realizations = [row.get("realization") if isinstance(row, dict) else None for row in record["realizations"]]
        if realizations != layout[record["index"]]:
            raise Damaged(f"its realizations {realizations} are not chunk {record['index']}'s {layout[record['index']]}")
        for row in record["realizations"]:
            require(row, {"levels": list}, f"realization {row['realization']}'s ")
            if len(row["levels"]) != levels or not all(isinstance(level, dict) and set(level) == set(DAMPERS)
                                                        for level in row["levels"]):
                raise Damaged(f"realization {row['realization']} has not one record with and without the damper "
                              f"at each of the {levels} levels")
    return check


def tasks(spec: RandomSpec) -> list:
    plain = spec.to_dict()
    return [(number, march_chunk, (plain, number, chunk)) for number, chunk in enumerate(spec.chunks())]


def check_sample(spec: RandomSpec) -> list[int]:
    """The realizations the FMU checks: ``spec.confirm`` of them drawn with the seed (the saved one first)."""
    chosen = [] if spec.save_input is None else [spec.save_input]
    others = [r for r in range(spec.realizations) if r not in chosen]
    rng = np.random.default_rng(spec.seed)
    extra = max(spec.confirm - len(chosen), 0)
    chosen += sorted(int(r) for r in rng.choice(others, size=min(extra, len(others)), replace=False)) if others else []
    return chosen[:max(spec.confirm, len(chosen))] if spec.confirm else []


def check_tasks(spec: RandomSpec) -> list:
    """The FMU's checks as tasks (:func:`.trace.check_task`), at the first level."""
    from .trace import check_task

    plain = spec.to_dict()
    return [(r, check_task, (plain, r, 0)) for r in check_sample(spec)]


#: The stretch of the window ``history.png`` shows, s.
HISTORY_SPAN = 20.0


def write(spec: RandomSpec, done: dict, checks: list[dict], folder: Path, timing: dict) -> dict:
    """Write the files (see the module's text); return the summary."""
    from ...excitation import oracle, replay_rows, write_replay_csv
    from . import figures
    from .trace import trace, verdict

    load = spec.values["R_load"]
    summary = summarize(spec, done, load)
    frequencies, densities = psd(spec, done)
    for k, entry in enumerate(summary["levels"]):
        if spec.source["kind"] == "record":  # its samples' RMS: a record has no spectrum to integrate
            entry["base_acceleration_rms"] = float(np.sqrt(np.mean(np.square(spec.source["acceleration"]))))
            entry["without"]["rms_relative_linear"] = None
            continue
        excitation = spec.excitation(k)
        entry["base_acceleration_rms"] = math.sqrt(oracle.acceleration_variance(excitation))
        entry["without"]["rms_relative_linear"] = math.sqrt(oracle.relative_displacement_variance(
            excitation, spec.values["M"], spec.values["K"], spec.values["C"]))
    data = arrays(spec, done)
    finite = int(np.isfinite(data["rms_relative"][0, :, 0]).sum())
    spread = None if finite < 2 else {"rms_relative": float(np.nanstd(data["rms_relative"][0, :, 0], ddof=1)),
                                      "impacts": float(np.nanstd(data["impacts"][0, :, 0], ddof=1)),
                                      "count": finite}
    checks = [verdict(check, spread) for check in checks]
    _write_dataset(spec, data, frequencies, densities, folder / "random.nc")
    _write_csv(summary, folder / "random.csv")
    _write_psd(spec, frequencies, densities, folder / "psd.csv")
    report = {"study": "random", "excitation": spec.excitation(0).describe(), "levels_given": list(spec.levels),
              "settings": {key: value for key, value in spec.to_dict().items() if key not in ("source", "values")},
              "warmup_s": spec.warmup, "window_s": spec.duration, "step_s": spec.step, "values": spec.values,
              "without_damper": {"d": spec.without["d"], "why": "a gap no displacement of the record reaches: the "
                                 "main mass, spring and damper alone"},
              "start": {"p0": 0.0, "q0": 0.0, "dp0": 0.0, "dq0": 0.0,
                        "why": "every realization starts from rest, the base too (y = 0)"},
              **summary, "fmu_checks": {"checked": len(checks), "agree": sum(1 for c in checks if c["agrees"]),
                                        "seconds": timing.get("checking_s"), "checks": checks},
              "wall_s": timing.get("marching_s", 0.0) + timing.get("checking_s", 0.0), **timing}
    shown = spec.save_input if spec.save_input is not None else 0
    steps = spec.steps if spec.save_input is not None else min(spec.steps, spec.warmup_steps +
                                                                 int(round(HISTORY_SPAN / spec.step)))
    traces = {case: trace(spec, shown, 0, steps, case) for case in DAMPERS}
    if spec.save_input is not None:
        excitation = spec.excitation(0)
        write_replay_csv(folder / f"input_{shown}.csv", replay_rows(excitation, shown, spec.steps))
        _write_response(traces["with"], spec, folder / f"response_{shown}.csv")
        report["saved"] = {"realization": shown, "input": f"input_{shown}.csv", "response": f"response_{shown}.csv",
                           "step_s": spec.step, "stop_time_s": spec.steps * spec.step,
                           "replay": "fmpy.simulate_fmu(fmu, start_values=summary['values'], input=rows of input_K.csv, "
                                     "step_size=step_s, output_interval=step_s, stop_time=stop_time_s)"}
    write_json(folder / "summary.json", report)
    natural = math.sqrt(spec.values["K"] / spec.values["M"]) / (2.0 * math.pi)
    linear = {} if spec.source["kind"] == "record" else {
        0: oracle.relative_displacement_psd(spec.excitation(0), frequencies, spec.values["M"], spec.values["K"],
                                            spec.values["C"])}
    figures.effectiveness(report, folder / "effectiveness.png")
    figures.spectra(frequencies, densities, linear, natural, folder / "psd.png")
    figures.history(traces["with"], traces["without"], spec.warmup, HISTORY_SPAN, folder / "history.png")
    figures.peaks(list(spec.levels), data["peak"], folder / "peaks.png")
    return report


def _write_response(trace: dict, spec: RandomSpec, path: Path) -> None:
    """``response_K.csv``: the time (s) of each step's start and of the record's end, the main mass's
    displacement (m) and the impacts so far there, as the FMU reports them after each step."""
    times = spec.step * np.arange(len(trace["time"]) + 1)
    positions = np.concatenate([[0.0], trace["main_displacement"]])
    counts = np.concatenate([[0], trace["impact_count"]])
    lines = ["time,main_displacement,impact_count"]
    lines += [f"{t!r},{p!r},{int(c)}" for t, p, c in zip(times.tolist(), positions.tolist(), counts.tolist())]
    path.write_text("\n".join(lines) + "\n")


def _write_dataset(spec: RandomSpec, data: dict, frequencies, densities, path: Path) -> None:
    import xarray as xr

    levels = max(len(spec.levels), 1)
    coords = {"level": ("level", list(spec.levels) if spec.levels else [math.nan],
                        {"units": "(m/s^2)^2/Hz", "description": "the spectrum's level (one-sided PSD of the base "
                                                                 "acceleration)"}),
              "realization": np.arange(spec.realizations), "damper": list(DAMPERS),
              "frequency": ("frequency", frequencies, {"units": "Hz"})}
    variables = {name: (("level", "realization", "damper"), data[name], {"units": unit, "description": text})
                 for name, (unit, text) in MEASURES.items()}
    psd_array = np.full((levels, len(DAMPERS), len(frequencies)), np.nan)
    for (k, case), density in densities.items():
        psd_array[k, DAMPERS.index(case)] = density
    variables["psd_relative"] = (("level", "damper", "frequency"), psd_array,
                                 {"units": "m^2/Hz", "description": "one-sided PSD of the relative displacement "
                                                                    "(Welch, Hann, half overlap)"})
    xr.Dataset(variables, coords=coords, attrs={"psd_convention": "one-sided, per hertz"}).to_netcdf(
        path, engine="h5netcdf")


def _write_csv(summary: dict, path: Path) -> None:
    names = ("rms_relative", "rms_absolute", "peak_median", "peak_p95", "impacts_per_second", "power", "v_rms")
    units = ("m", "m", "m", "m", "1/s", "W", "V")
    header = ["level_m2_per_s4_per_Hz", "base_acceleration_rms_m_per_s2", "damper", "ratio", "ratio_low", "ratio_high"]
    for name, unit in zip(names, units):
        header += [f"{name}_{unit}".replace("/", "_per_"), f"{name}_low", f"{name}_high"]
    rows = [",".join(header)]
    for entry in summary["levels"]:
        for case in DAMPERS:
            values = [entry["level"], entry.get("base_acceleration_rms"), case,
                      *((entry["ratio"], *entry["ratio_ci"]) if case == "with" else (None, None, None))]
            for name in names:
                values += [entry[case][name], *entry[case][f"{name}_ci"]]
            rows.append(",".join("" if v is None else repr(v) if isinstance(v, float) else str(v) for v in values))
    path.write_text("\n".join(rows) + "\n")


def _write_psd(spec: RandomSpec, frequencies, densities, path: Path) -> None:
    from ...excitation import oracle

    header = ["frequency_Hz"]
    columns = [frequencies]
    for k in range(max(len(spec.levels), 1)):
        for case in DAMPERS:
            if (k, case) in densities:
                header.append(f"psd_{case}_level{k}_m2_per_Hz")
                columns.append(densities[k, case])
        if spec.source["kind"] != "record":
            header.append(f"psd_linear_level{k}_m2_per_Hz")
            columns.append(oracle.relative_displacement_psd(spec.excitation(k), frequencies, spec.values["M"],
                                                            spec.values["K"], spec.values["C"]))
    table = np.column_stack(columns)
    lines = [",".join(header)] + [",".join(repr(float(x)) for x in row) for row in table]
    path.write_text("\n".join(lines) + "\n")
