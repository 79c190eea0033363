"""The results of a frequency response (:mod:`piezo_fmu_harness.studies.forced.chains`): the
dataset over ``(damper, direction, omega)``, where the two sweep directions differ, the summary
(resonant amplitude with and without the damper, the band where it helps, the best harvested power,
the unstable orbits met) and the files: ``frequency_response.nc`` (xarray, units in attributes),
``frequency_response.csv``, ``unstable_orbits.csv``, ``summary.json`` and the figures ``amplitude.png``, ``power.png``, ``impacts.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import Optional

import numpy as np

from ...datasets import bands
from ...wording import counted
from ...fmu import FmuModel
from ...periodic.band import DAMPER_CASES, FrequencySpec, linear_transmissibility
from .chains import BAND_TOLERANCE, CHAINS, DIRECTIONS, MEASURES, FrequencyRun


def build_dataset(spec: FrequencySpec, records: dict, model: FmuModel):
    """The study as an ``xarray.Dataset`` over ``(damper, direction, omega)``; unfinished points
    are NaN (``status`` missing)."""
    import xarray as xr

    count = len(spec.ratios)
    shape = (len(DAMPER_CASES), len(DIRECTIONS), count)
    data = {key: np.full(shape, np.nan) for key in MEASURES}
    settled = np.zeros(shape, dtype=np.int8)
    method = np.full(shape, "missing", dtype=object)
    verdict = np.full(shape, "missing", dtype=object)
    motion = np.full(shape, "missing", dtype=object)
    error = np.full(shape, "", dtype=object)
    multipliers = np.full(shape + (4,), complex(np.nan, np.nan))
    for chain, (damper, direction) in enumerate(CHAINS):
        position = (DAMPER_CASES.index(damper), DIRECTIONS.index(direction))
        for frequency in range(count):
            record = records.get(spec.index(chain, frequency))
            if record is None:
                continue
            where = (*position, frequency)
            for key in MEASURES:
                value = record.get(key)
                if key == "unstable_orbits":
                    value = len(value or ())
                data[key][where] = np.nan if value is None else value
            data["order"][where] = record.get("order") or 0
            settled[where] = bool(record.get("settled"))
            method[where] = record.get("method") if record["status"] == "ok" else "error"
            verdict[where] = record.get("verdict", "error") if record["status"] == "ok" else "error"
            motion[where] = record.get("motion", "error") if record["status"] == "ok" else "error"
            error[where] = record.get("error") or ""
            for k, (real, imag) in enumerate(record.get("multipliers") or ()):
                multipliers[(*where, k)] = complex(real, imag)

    omegas = spec.omegas
    dims = ("damper", "direction", "omega")
    variables = {key: (dims, values, {"units": MEASURES[key][0], "long_name": MEASURES[key][1]})
                 for key, values in data.items()}
    variables["settled"] = (dims, settled, {"units": "1", "long_name": "1: a stable periodic orbit was found, verified "
                                                                    "and checked; 0: none within the cap on cycles "
                                                                    "(the motion is reported as undecided)"})
    variables["method"] = (dims, method.astype(str), {"long_name": "newton, marching, none (undecided), error "
                                                                   "(the FMU rejected the point) or missing"})
    variables["verdict"] = (dims, verdict.astype(str), {"long_name": "stable (the response is a stable orbit), "
                                                                     "undecided (none reached within the cap), error "
                                                                     "or missing"})
    variables["motion"] = (dims, motion.astype(str), {"long_name": "periodic (a stable orbit), undecided, "
                                                                   "or undecided (converging): its exponent says it "
                                                                   "still contracts; never chaotic"})
    for part, values in (("real", multipliers.real), ("imag", multipliers.imag)):
        variables[f"multiplier_{part}"] = (dims + ("multiplier",), values,
                                           {"units": "1", "long_name": f"{part} part of the orbit's Floquet multipliers, "
                                                                       "by decreasing modulus (NaN: not periodic)"})
    variables["error"] = (dims, error.astype(str), {"long_name": "the FMU's message for a rejected point"})
    differ = directions_differ(data, settled)
    variables["directions_differ"] = (("damper", "omega"), differ.astype(np.int8),
                                      {"units": "1", "long_name": "1: up and down sweeps settled on different orbits "
                                                                  f"(order, impacts per cycle, or amplitude beyond "
                                                                  f"{BAND_TOLERANCE:g} relative)"})
    parameters = {**model.defaults(), **spec.values}
    variables["transmissibility_linear"] = (("omega",), linear_transmissibility(omegas, parameters["M"], parameters["K"],
                                                                                parameters["C"]),
                                            {"units": "1", "long_name": "|X/Y| of the main mass alone (closed form)"})
    coords = {
        "damper": ("damper", list(DAMPER_CASES), {"long_name": "with the damper, or without (gap widened)"}),
        "direction": ("direction", list(DIRECTIONS), {"long_name": "sweep direction in frequency"}),
        "omega": ("omega", omegas, {"units": "rad/s", "long_name": "forcing angular frequency"}),
        "ratio": ("omega", np.array(spec.ratios), {"units": "1", "long_name": "w / sqrt(K/M)"}),
        "base_amplitude": ("omega", np.array([spec.base_amplitude(w) for w in omegas]),
                           {"units": "m", "long_name": "base displacement amplitude Y"}),
    }
    attrs = {
        "title": "piezo-impact damper: frequency response to harmonic base motion",
        "natural_frequency_rad_per_s": spec.natural,
        "excitation": (f"y = Y sin(w t), Y = {spec.amplitude:g} m" if spec.amplitude is not None
                       else f"y = Y sin(w t), Y = A / w^2, A = {spec.acceleration:g} m/s^2"),
        "parameters": json.dumps(spec.values),
        "parameters_not_listed": "the FMU's start values (the nominal case)",
        "without_damper": f"the same FMU with the gap d = {spec.wide_gap:g} m (no impact possible)",
        "settings": json.dumps(asdict(spec.settings)),
        "tolerance_m": "settings.tolerance * Y: the section's return distance max(|dp|, |dp'|/w, |dq|, |dq'|/w)",
        "fmu": str(model.path),
        "fmu_guid": model.guid,
    }
    variables.update(unstable_variables(spec, records))
    return xr.Dataset(variables, coords=coords, attrs=attrs)


#: Columns of the unstable orbits' table, with units and descriptions.
UNSTABLE_COLUMNS = {
    "amplitude": ("m", "amplitude of the main mass on the unstable orbit"),
    "impacts_per_cycle": ("1", "impacts per forcing cycle on the unstable orbit"),
    "order": ("1", "period of the unstable orbit in forcing periods"),
    "max_multiplier": ("1", "largest modulus of its Floquet multipliers (> 1: unstable)"),
    "multiplier_error": ("1", "accuracy of max_multiplier"),
    "harvested_power": ("W", "mean harvested power on the unstable orbit"),
}


def unstable_variables(spec: FrequencySpec, records: dict) -> dict:
    """The unstable orbits met at every point, as variables over an ``unstable`` dimension: where
    each was met (damper, direction, omega) and what it is. They are never the response; they are
    what a continuation of the branches builds on."""
    rows = []
    for chain, (damper, direction) in enumerate(CHAINS):
        for frequency in range(len(spec.ratios)):
            record = records.get(spec.index(chain, frequency)) or {}
            for orbit in record.get("unstable_orbits") or ():
                rows.append((damper, direction, float(spec.omegas[frequency]), spec.ratios[frequency], orbit))
    dims = ("unstable",)
    variables = {
        "unstable_damper": (dims, np.array([r[0] for r in rows], dtype=str), {"long_name": "with or without the damper"}),
        "unstable_direction": (dims, np.array([r[1] for r in rows], dtype=str),
                               {"long_name": "the sweep that met the orbit"}),
        "unstable_omega": (dims, np.array([r[2] for r in rows], dtype=float),
                           {"units": "rad/s", "long_name": "forcing frequency of the unstable orbit"}),
        "unstable_ratio": (dims, np.array([r[3] for r in rows], dtype=float), {"units": "1", "long_name": "w / sqrt(K/M)"}),
        "unstable_verdict": (dims, np.array([r[4]["verdict"] for r in rows], dtype=str),
                             {"long_name": "unstable, or marginal (within its error of 1)"}),
    }
    for key, (units, text) in UNSTABLE_COLUMNS.items():
        variables[f"unstable_{key}"] = (dims, np.array([float(r[4][key]) for r in rows], dtype=float),
                                        {"units": units, "long_name": text})
    return variables


def directions_differ(data: dict, settled: np.ndarray) -> np.ndarray:
    """``(damper, omega)``: where both directions settled on different orbits."""
    both = (settled[:, 0, :] == 1) & (settled[:, 1, :] == 1)
    amplitude, impacts, order = data["amplitude"], data["impacts_per_cycle"], data["order"]
    with np.errstate(invalid="ignore"):
        apart = np.abs(amplitude[:, 0, :] - amplitude[:, 1, :]) > BAND_TOLERANCE * np.fmax(amplitude[:, 0, :],
                                                                                            amplitude[:, 1, :])
    other = (order[:, 0, :] != order[:, 1, :]) | (impacts[:, 0, :] != impacts[:, 1, :])
    return both & (apart | other)


def summarize(ds) -> dict:
    """What a designer asks: the resonant amplitude with and without the damper, the band where
    the damper lowers it, the best harvested power and where, the jump bands, where the motion is
    undecided, and the unstable orbits met. The response at a frequency is its stable orbit or,
    where none was reached within the cap, the undecided motion (measured over its window); unstable
    orbits never count."""
    ratios = ds["ratio"].values
    verdict = ds["verdict"].values
    settled = ds["settled"].values == 1
    response = (verdict == "stable") | (verdict == "undecided")
    amplitude = np.where(response, ds["amplitude"].values, np.nan)
    power = np.where(response, ds["harvested_power"].values, np.nan)
    report = {"excitation": ds.attrs["excitation"], "natural_frequency_rad_per_s": ds.attrs["natural_frequency_rad_per_s"],
              "points": int(ds["amplitude"].size), "undecided": {}, "resonant_amplitude_m": {},
              "damper_helps": {}, "best_harvested_power": {}, "jump_bands": {}, "unstable_orbits_met": {}}
    for i, damper in enumerate(DAMPER_CASES):
        report["jump_bands"][damper] = bands(ratios, ds["directions_differ"].values[i] == 1)
        for j, direction in enumerate(DIRECTIONS):
            key = f"{damper} the damper, sweep {direction}"
            loose = verdict[i, j] == "undecided"
            report["undecided"][key] = {f"{r:.6g}": str(m) for r, m in zip(ratios[loose], ds["motion"].values[i, j][loose])}
            met = ((ds["unstable_damper"].values == damper) & (ds["unstable_direction"].values == direction))
            report["unstable_orbits_met"][key] = {
                "count": int(met.sum()),
                "largest_multiplier": float(ds["unstable_max_multiplier"].values[met].max()) if met.any() else None}
            row = amplitude[i, j]
            if np.isfinite(row).any():
                k = int(np.nanargmax(row))
                report["resonant_amplitude_m"][key] = {"amplitude_m": float(row[k]), "at_ratio": float(ratios[k]),
                                                       "transmissibility": float(ds["transmissibility"].values[i, j, k]),
                                                       "motion": _motion(settled[i, j, k])}
    for j, direction in enumerate(DIRECTIONS):
        with np.errstate(invalid="ignore"):  # lower beyond rounding: a no-impact orbit is the same with and without
            helps = amplitude[0, j] < (1.0 - BAND_TOLERANCE) * amplitude[1, j]
        report["damper_helps"][direction] = {
            "bands": bands(ratios, helps),
            "peak_ratio_with_over_without": _ratio(np.nanmax(amplitude[0, j]) if np.isfinite(amplitude[0, j]).any()
                                                   else None,
                                                   np.nanmax(amplitude[1, j]) if np.isfinite(amplitude[1, j]).any()
                                                   else None),
        }
        row = power[0, j]
        if np.isfinite(row).any() and np.nanmax(row) > 0:
            k = int(np.nanargmax(row))
            report["best_harvested_power"][direction] = {"power_W": float(row[k]), "at_ratio": float(ratios[k]),
                                                         "amplitude_m": float(amplitude[0, j, k]),
                                                         "impacts_per_cycle": float(ds["impacts_per_cycle"].values[0, j, k]),
                                                         "motion": _motion(settled[0, j, k])}
    return report


def _motion(settled: bool) -> str:
    return "stable orbit" if settled else "undecided"


def _ratio(a, b) -> Optional[float]:
    return float(a) / float(b) if a is not None and b else None


def summary_lines(report: dict) -> list[str]:
    """Human-readable lines for :func:`summarize`'s report."""
    def mm(value):
        return f"{1e3 * value:.4g} mm"

    lines = [f"frequency response ({report['excitation']}; w_n = sqrt(K/M) = "
             f"{report['natural_frequency_rad_per_s']:.4g} rad/s; {counted(report['points'], 'point')}):"]
    for key, peak in report["resonant_amplitude_m"].items():
        lines.append(f"  peak amplitude {key}: {mm(peak['amplitude_m'])} at w/w_n = {peak['at_ratio']:.4g} "
                     f"(transmissibility {peak['transmissibility']:.4g}, {peak['motion']})")
    for direction, helps in report["damper_helps"].items():
        shown = ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in helps["bands"]) or "nowhere"
        ratio = helps["peak_ratio_with_over_without"]
        lines.append(f"  sweep {direction}: the damper lowers the amplitude at w/w_n {shown}; peak with / without = "
                     f"{'n/a' if ratio is None else f'{ratio:.4g}'}")
    for direction, best in report["best_harvested_power"].items():
        lines.append(f"  best harvested power (sweep {direction}): {1e3 * best['power_W']:.4g} mW at w/w_n = "
                     f"{best['at_ratio']:.4g} ({best['impacts_per_cycle']:.4g} impacts per cycle, amplitude "
                     f"{mm(best['amplitude_m'])}, {best['motion']})")
    for damper, runs in report["jump_bands"].items():
        if runs:
            lines.append(f"  up and down sweeps differ {damper} the damper at w/w_n "
                         + ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in runs))
    unsettled = {key: values for key, values in report["undecided"].items() if values}
    for key, values in unsettled.items():
        lines.append(f"  undecided (no stable orbit reached within the cap; measured over a window) {key}: "
                     f"{counted(len(values), 'point')}, at w/w_n " + ", ".join(f"{r} ({m})" for r, m in values.items()))
    for key, met in report["unstable_orbits_met"].items():
        if met["count"]:
            lines.append(f"  unstable orbits met and set aside {key}: {met['count']} "
                         f"(largest multiplier {met['largest_multiplier']:.4g})")
    return lines


def tidy_frame(ds):
    """One row per point: damper, direction, frequency and every measure."""
    extra = [name for name in ds.data_vars if ds[name].dims in (("unstable",), ds["multiplier_real"].dims)]
    frame = ds.drop_vars(["directions_differ", "transmissibility_linear", *extra]).to_dataframe().reset_index()
    frame["order"] = frame["order"].astype("Int64")
    for k in range(ds.sizes["multiplier"]):
        for part in ("real", "imag"):
            frame[f"multiplier_{k + 1}_{part}"] = ds[f"multiplier_{part}"].isel(multiplier=k).values.ravel()
    return frame


def unstable_frame(ds):
    """One row per unstable orbit met: where, and what it is."""
    import pandas as pd

    names = [name for name in ds.data_vars if ds[name].dims == ("unstable",)]
    return pd.DataFrame({name.removeprefix("unstable_"): ds[name].values for name in names})


def finish(model: FmuModel, run: FrequencyRun, jobs: int = 1) -> dict:
    """Write the Dataset, the CSV, the summary and the figures (drawn in ``jobs`` processes), after
    return ``{"dataset", "summary", "files"}``."""
    from ...datasets import csv_frame, save_dataset, units_of
    from ...drawing import Rendering
    from .figures import frequency_figure_calls

    ds = build_dataset(run.spec, run.done, model)
    report = summarize(ds)
    rendering = Rendering(frequency_figure_calls(ds, run.folder), jobs)
    files = [run.folder / "frequency_response.nc", run.folder / "frequency_response.csv", run.folder / "summary.json",
             run.folder / "unstable_orbits.csv"]
    save_dataset(ds, files[0])
    units = units_of(ds)
    csv_frame(tidy_frame(ds), {**units, **{f"multiplier_{k + 1}_{part}": "1" for k in range(4) for part in ("real", "imag")}}
              ).to_csv(files[1], index=False)
    files[2].write_text(json.dumps(report, indent=2) + "\n")
    csv_frame(unstable_frame(ds), {name.removeprefix("unstable_"): unit for name, unit in units.items()
                                   if name.startswith("unstable_")}).to_csv(files[3], index=False)
    return {"dataset": ds, "summary": report, "files": files + rendering.wait()}


