"""The load of the circuit voltage models: a load sweep through the FMU with fmpy.

**Load sweep** (``piezo-fmu load-sweep``). ``R_load`` log-spaced over at least four decades, for
``voltage_model`` 1 (circuit, one-way) and 2 (circuit, coupled); each point is one run of the
nominal case (or ``--set`` changes) from the release. Per point: the energy harvested in both
loads (and per barrier), the energy per impact ``harvested_energy / impact_count`` and the
average power ``harvested_energy / stop_time``. The optimum of each is the best sampled load,
refined by the parabola in ``log10 R`` through the logarithms of the best value and its two
neighbours (when the best is not at an end of the range). Beside it: the estimate
``R_opt ~ 1 / (omega_c C_p)``, with ``C_p`` (``patch_capacitance``) and ``omega_c``
(``contact_frequency``) read from the FMU's calculated parameters. Writes ``load_sweep.csv``,
``load_sweep.json``, ``load_sweep.md`` and ``load_sweep.png``; the points run on the engine and are
recorded as they finish (:mod:`piezo_fmu_harness.studies.load.points`, ``--resume``).

The single impact is in :mod:`piezo_fmu_harness.studies.load.impacts`.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional

import numpy as np

from ...circuit import circuit_constants
from ...drawing import ohms
from ...fmu import FmuModel, Instance, discard
from ...series import write_csv
from ...store import jsonable
from ...wording import counted

MODEL_NAMES = {0: "quasi-static (open circuit)", 1: "circuit, one-way", 2: "circuit, coupled"}
#: The models that harvest energy (model 0 is an open-circuit voltage: nothing flows).
CIRCUIT_MODELS = (1, 2)
#: The files a load sweep writes (besides :data:`piezo_fmu_harness.studies.load.impacts.FILES`).
FILES = ("load_sweep.csv", "load_sweep.json", "load_sweep.md", "load_sweep.png")
#: Default loads: 1 kOhm to 1 GOhm, four points a decade. A 2 s point of model 2 costs about
#: 12 s of CPU at 1 kOhm (its cost grows as 1/R; 25 s for all its loads), model 1 about 0.02 s
#: whatever the load.
DEFAULT_R_MIN, DEFAULT_R_MAX, DEFAULT_COUNT = 1e3, 1e9, 25


# -- loads and constants ---------------------------------------------------------------------------

def log_loads(r_min: float, r_max: float, count: int) -> tuple[float, ...]:
    """``count`` loads (Ohm) evenly spaced in ``log10 R`` from ``r_min`` to ``r_max``."""
    values = np.logspace(math.log10(r_min), math.log10(r_max), count)
    # 12 significant digits: 1778.27941004 rather than 1778.2794100389228; ends exact.
    return tuple(float(f"{v:.12g}") for v in values)


def ohm_text(value: float) -> str:
    """A resistance as ``52 kOhm``, ``3.59 MOhm``."""
    return ohms(value, "Ohm")


# -- metrics and the optimum -----------------------------------------------------------------------

def point_metrics(record: dict, stop_time: float) -> dict:
    """A load-sweep point's metrics (SI) from an :meth:`Instance.run_point` record."""
    def number(key):
        value = record.get(key)
        return float("nan") if value is None else float(value)

    energy, count = number("harvested_energy"), number("impact_count")
    return {
        "impact_count": count,
        "harvested_energy_J": energy,
        "harvested_energy_left_J": number("harvested_energy_left"),
        "harvested_energy_right_J": number("harvested_energy_right"),
        "energy_per_impact_J": energy / count if count > 0 else float("nan"),
        "average_power_W": energy / stop_time,
        "seconds": number("seconds"),
    }


def find_optimum(loads, values) -> dict:
    """The load that maximizes ``values``: the best sampled point, and the vertex of the
    parabola in ``log10 R`` through the logarithms of the best value and its two neighbours
    (``None`` when the best point is at an end of the range, or a neighbour is missing)."""
    loads, values = np.asarray(loads, float), np.asarray(values, float)
    if not np.isfinite(values).any():
        return {"index": None, "R_ohm": None, "value": None, "R_refined_ohm": None, "value_refined": None,
                "bracketed": False}
    best = int(np.nanargmax(values))
    result = {"index": best, "R_ohm": float(loads[best]), "value": float(values[best]),
              "R_refined_ohm": None, "value_refined": None, "bracketed": False}
    if 0 < best < len(values) - 1:
        three = values[best - 1:best + 2]
        if np.all(np.isfinite(three)) and np.all(three > 0):
            u = np.log10(loads[best - 1:best + 2])
            a, b, c = np.polyfit(u, np.log(three), 2)
            if a < 0:
                vertex = -b / (2 * a)
                result.update(R_refined_ohm=float(10 ** vertex),
                              value_refined=float(np.exp(np.polyval([a, b, c], vertex))), bracketed=True)
    return result


def end_slopes(loads, values) -> dict:
    """``d ln(value) / d ln(R)`` between the two lowest and the two highest loads: +1 and -1
    are the small- and large-R limits of the energy harvested per impact."""
    loads, values = np.asarray(loads, float), np.asarray(values, float)

    def slope(i, j):
        if values[i] > 0 and values[j] > 0:
            return float(math.log(values[j] / values[i]) / math.log(loads[j] / loads[i]))
        return None

    return {"low_R": slope(0, 1), "high_R": slope(-2, -1)}


# -- the load sweep --------------------------------------------------------------------------------

def write_load_sweep(model: FmuModel, out: Path, instance: Instance, records: dict, models, loads, stop_time: float,
                     step: float, overrides: dict, seconds: float, backend: str) -> dict:
    """Write the load sweep's files into ``out`` from its finished points, ``records`` by index
    (:func:`piezo_fmu_harness.studies.load.points.points`: each model's loads, then the paper's load).

    ``instance`` reads the circuit's constants; ``seconds`` and ``backend`` say how long the points
    took and where. Returns the summary written to ``load_sweep.json``.
    """
    out = Path(out)
    loads = tuple(loads)
    nominal_load = float(model.parameters["R_load"].start)
    values = {m: {**overrides, "voltage_model": m} for m in models}
    constants = {m: circuit_constants(instance, values[m]) for m in models}
    records = {(m, i): records[j * (len(loads) + 1) + i] for j, m in enumerate(models) for i in range(len(loads) + 1)}

    failed = {f"model {m}, R_load = {record['values']['R_load']:g} Ohm": record["error"]
              for (m, _), record in sorted(records.items()) if record["status"] != "ok"}
    rows, per_model = [], {}
    for m in models:
        metrics = [point_metrics(records[m, i], stop_time) for i in range(len(loads))]
        for r, point in zip(loads, metrics):
            rows.append({"voltage_model": m, "R_load_ohm": r, **point})
        energy = [p["energy_per_impact_J"] for p in metrics]
        power = [p["average_power_W"] for p in metrics]
        per_model[str(m)] = {
            "name": MODEL_NAMES[m],
            **constants[m],
            "optimum": {"energy_per_impact_J": find_optimum(loads, energy),
                        "average_power_W": find_optimum(loads, power)},
            "nominal_load": {"R_load_ohm": nominal_load,
                             **point_metrics(records[m, len(loads)], stop_time)},
            "slopes_energy_per_impact": end_slopes(loads, energy),
            "cpu_seconds": sum(records[m, i]["cpu_seconds"] for i in range(len(loads) + 1)),
        }
    files = {"csv": out / "load_sweep.csv", "json": out / "load_sweep.json", "table": out / "load_sweep.md"}
    write_csv(files["csv"], {key: [row[key] for row in rows] for key in rows[0] if key != "seconds"})
    summary = {
        "case": "nominal (docs/model.md section 7) from the release; every point one run from t = 0",
        "duration_s": stop_time,
        "communication_step_s": step,
        "loads_ohm": list(loads),
        "decades": math.log10(loads[-1] / loads[0]),
        "overrides": overrides,
        "models": per_model,
        "failed_points": failed,
        "wall_seconds": seconds,
        "backend": backend,
        "fmu": {"path": str(model.path), "guid": model.guid},
        "optimum_method": ("best sampled load; refined: vertex of the parabola in log10 R through ln(value) at "
                           "the best load and its two neighbours"),
    }

    from . import figures as curves

    files["figure"] = curves.load_sweep_figure(rows, summary, out)
    summary["files"] = {key: str(path) for key, path in files.items()}
    files["table"].write_text(markdown_table(summary, rows))
    files["json"].write_text(json_text(summary))
    return summary


def best_load(summary: dict) -> Optional[float]:
    """The measured optimum of the average power of the first model swept (refined if it can;
    ``None`` if no point ran)."""
    optimum = next(iter(summary["models"].values()))["optimum"]["average_power_W"]
    return optimum["R_refined_ohm"] or optimum["R_ohm"]


def json_text(value) -> str:
    """``value`` as JSON text, NaN (a metric left undefined) written as null."""
    return json.dumps(jsonable(value), indent=2, allow_nan=False) + "\n"


def _optimum_cells(optimum: dict, factor: float) -> str:
    if optimum["index"] is None:
        return "n/a | n/a | n/a"
    refined = (f"{ohm_text(optimum['R_refined_ohm'])} ({optimum['value_refined'] * factor:.4g})"
               if optimum["bracketed"] else "at the range's end: not bracketed")
    return f"{ohm_text(optimum['R_ohm'])} | {optimum['value'] * factor:.4g} | {refined}"


def markdown_table(summary: dict, rows: list[dict]) -> str:
    """The optimum of each model beside the estimate, then every point."""
    lines = [
        "# Load sweep",
        "",
        f"Duration simulated: **{summary['duration_s']:g} s** per point from the nominal release, through the FMU "
        f"with fmpy (communication step {summary['communication_step_s']:g} s); loads "
        f"{ohm_text(summary['loads_ohm'][0])} to {ohm_text(summary['loads_ohm'][-1])}, "
        f"{counted(len(summary['loads_ohm']), 'point')} ({summary['decades']:.3g} decades)."
        + (f" Changed parameters: {summary['overrides']}." if summary["overrides"] else ""),
        "",
        "| model | R_opt ~ 1/(omega_c C_p) | best load, energy/impact | energy/impact (uJ) | refined (uJ) "
        "| best load, power | average power (mW) | refined (mW) "
        f"| at R_load = {ohm_text(next(iter(summary['models'].values()))['nominal_load']['R_load_ohm'])}: "
        "uJ/impact, mW |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m, entry in summary["models"].items():
        nominal = entry["nominal_load"]
        lines.append(
            f"| {m} ({entry['name']}) | {ohm_text(entry['R_opt_estimate_ohm'])} "
            f"| {_optimum_cells(entry['optimum']['energy_per_impact_J'], 1e6)} "
            f"| {_optimum_cells(entry['optimum']['average_power_W'], 1e3)} "
            f"| {nominal['energy_per_impact_J'] * 1e6:.4g}, {nominal['average_power_W'] * 1e3:.4g} |")
    entry = next(iter(summary["models"].values()))
    lines += [
        "",
        f"`C_p` = {entry['patch_capacitance_F']:.4g} F, `omega_c` = {entry['contact_frequency_rad_per_s']:.4g} rad/s "
        "(the FMU's `patch_capacitance` and `contact_frequency`). Refined: "
        f"{summary['optimum_method'].split('refined: ')[1]}.",
        "",
        "| model | R_load (Ohm) | impacts | harvested (uJ) | left (uJ) | right (uJ) | per impact (uJ) | power (mW) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(f"| {row['voltage_model']} | {row['R_load_ohm']:.4g} | {row['impact_count']:.0f} "
                     f"| {row['harvested_energy_J'] * 1e6:.5g} | {row['harvested_energy_left_J'] * 1e6:.5g} "
                     f"| {row['harvested_energy_right_J'] * 1e6:.5g} | {row['energy_per_impact_J'] * 1e6:.5g} "
                     f"| {row['average_power_W'] * 1e3:.5g} |")
    return "\n".join(lines) + "\n"


def summary_lines(summary: dict) -> list[str]:
    """What ``piezo-fmu load-sweep`` prints."""
    loads = summary["loads_ohm"]
    lines = [f"load sweep, {len(loads)} loads {ohm_text(loads[0])} to {ohm_text(loads[-1])}, "
             f"{summary['duration_s']:g} s each, {summary['wall_seconds']:.1f} s on {summary['backend']}"]
    for m, entry in summary["models"].items():
        estimate = ohm_text(entry["R_opt_estimate_ohm"])
        lines.append(f"  model {m} ({entry['name']}): R_opt ~ 1/(omega_c C_p) = {estimate}")
        for key, factor, unit in (("energy_per_impact_J", 1e6, "uJ per impact"), ("average_power_W", 1e3, "mW")):
            o = entry["optimum"][key]
            if o["index"] is None:
                lines.append(f"    {key}: no point ran")
                continue
            refined = (f", refined {ohm_text(o['R_refined_ohm'])}: {o['value_refined'] * factor:.4g} {unit}"
                       if o["bracketed"] else " (at the end of the range: widen it)")
            lines.append(f"    best {ohm_text(o['R_ohm'])}: {o['value'] * factor:.4g} {unit}{refined}")
    for point, error in summary["failed_points"].items():
        lines.append(f"  rejected by the FMU: {point}: {error}")
    lines.append(f"  files in {Path(summary['files']['json']).parent}")
    return lines


def cleanup(instance: Instance, unzipdir: str) -> None:
    """Free ``instance`` and remove the folder its FMU was extracted to."""
    instance.free()
    discard(unzipdir)
