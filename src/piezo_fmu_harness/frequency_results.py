"""The results of a frequency response (:mod:`piezo_fmu_harness.frequency_response`): the
dataset over ``(damper, direction, omega)``, where the two sweep directions differ, the summary
(resonant amplitude with and without the damper, the band where it helps, the best harvested power)
and the files: ``frequency_response.nc`` (xarray, units in attributes), ``frequency_response.csv``,
``summary.json`` and the figures ``amplitude.png``, ``power.png``, ``impacts.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import Optional

import numpy as np

from .analysis import bands
from .fmu import FmuModel
from .frequency_response import (BAND_TOLERANCE, CHAINS, DAMPER_CASES, DIRECTIONS, MEASURES, FrequencyRun,
                                 FrequencySpec, linear_transmissibility)


def build_dataset(spec: FrequencySpec, records: dict, model: FmuModel):
    """The study as an ``xarray.Dataset`` over ``(damper, direction, omega)``; unfinished points
    are NaN (``status`` missing)."""
    import xarray as xr

    count = len(spec.ratios)
    shape = (len(DAMPER_CASES), len(DIRECTIONS), count)
    data = {key: np.full(shape, np.nan) for key in MEASURES}
    settled = np.zeros(shape, dtype=np.int8)
    method = np.full(shape, "missing", dtype=object)
    error = np.full(shape, "", dtype=object)
    for chain, (damper, direction) in enumerate(CHAINS):
        position = (DAMPER_CASES.index(damper), DIRECTIONS.index(direction))
        for frequency in range(count):
            record = records.get(spec.index(chain, frequency))
            if record is None:
                continue
            where = (*position, frequency)
            for key in MEASURES:
                value = record.get(key)
                data[key][where] = np.nan if value is None else value
            data["order"][where] = record.get("order") or 0
            settled[where] = bool(record.get("settled"))
            method[where] = record.get("method") if record["status"] == "ok" else "error"
            error[where] = record.get("error") or ""

    omegas = spec.omegas
    dims = ("damper", "direction", "omega")
    variables = {key: (dims, values, {"units": MEASURES[key][0], "long_name": MEASURES[key][1]})
                 for key, values in data.items()}
    variables["settled"] = (dims, settled, {"units": "1", "long_name": "1: the steady state was found and verified; "
                                                                    "0: the cap on cycles was reached first"})
    variables["method"] = (dims, method.astype(str), {"long_name": "newton, marching, none (not settled), error "
                                                                   "(the FMU rejected the point) or missing"})
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
    return xr.Dataset(variables, coords=coords, attrs=attrs)


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
    the damper lowers it, the best harvested power and where, the jump bands, what did not settle."""
    ratios = ds["ratio"].values
    settled = ds["settled"].values == 1
    amplitude = np.where(settled, ds["amplitude"].values, np.nan)
    power = np.where(settled, ds["harvested_power"].values, np.nan)
    report = {"excitation": ds.attrs["excitation"], "natural_frequency_rad_per_s": ds.attrs["natural_frequency_rad_per_s"],
              "points": int(ds["amplitude"].size), "not_settled": {}, "resonant_amplitude_m": {},
              "damper_helps": {}, "best_harvested_power": {}, "jump_bands": {}}
    for i, damper in enumerate(DAMPER_CASES):
        report["jump_bands"][damper] = bands(ratios, ds["directions_differ"].values[i] == 1)
        for j, direction in enumerate(DIRECTIONS):
            key = f"{damper} the damper, sweep {direction}"
            report["not_settled"][key] = [float(r) for r in ratios[~settled[i, j]]]
            row = amplitude[i, j]
            if np.isfinite(row).any():
                k = int(np.nanargmax(row))
                report["resonant_amplitude_m"][key] = {"amplitude_m": float(row[k]), "at_ratio": float(ratios[k]),
                                                       "transmissibility": float(ds["transmissibility"].values[i, j, k])}
    for j, direction in enumerate(DIRECTIONS):
        with np.errstate(invalid="ignore"):
            helps = amplitude[0, j] < amplitude[1, j]
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
                                                         "impacts_per_cycle": float(ds["impacts_per_cycle"].values[0, j, k])}
    return report


def _ratio(a, b) -> Optional[float]:
    return float(a) / float(b) if a is not None and b else None


def summary_lines(report: dict) -> list[str]:
    """Human-readable lines for :func:`summarize`'s report."""
    def mm(value):
        return f"{1e3 * value:.4g} mm"

    lines = [f"frequency response ({report['excitation']}; w_n = sqrt(K/M) = "
             f"{report['natural_frequency_rad_per_s']:.4g} rad/s; {report['points']} points):"]
    for key, peak in report["resonant_amplitude_m"].items():
        lines.append(f"  peak amplitude {key}: {mm(peak['amplitude_m'])} at w/w_n = {peak['at_ratio']:.4g} "
                     f"(transmissibility {peak['transmissibility']:.4g})")
    for direction, helps in report["damper_helps"].items():
        shown = ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in helps["bands"]) or "nowhere"
        ratio = helps["peak_ratio_with_over_without"]
        lines.append(f"  sweep {direction}: the damper lowers the amplitude at w/w_n {shown}; peak with / without = "
                     f"{'n/a' if ratio is None else f'{ratio:.4g}'}")
    for direction, best in report["best_harvested_power"].items():
        lines.append(f"  best harvested power (sweep {direction}): {1e3 * best['power_W']:.4g} mW at w/w_n = "
                     f"{best['at_ratio']:.4g} ({best['impacts_per_cycle']:.4g} impacts per cycle, amplitude "
                     f"{mm(best['amplitude_m'])})")
    for damper, runs in report["jump_bands"].items():
        if runs:
            lines.append(f"  up and down sweeps differ {damper} the damper at w/w_n "
                         + ", ".join(f"{lo:.4g}-{hi:.4g}" for lo, hi in runs))
    unsettled = {key: values for key, values in report["not_settled"].items() if values}
    for key, values in unsettled.items():
        lines.append(f"  not settled within the cap ({key}): {len(values)} points, at w/w_n "
                     + ", ".join(f"{v:.4g}" for v in values))
    return lines


def tidy_frame(ds):
    """One row per point: damper, direction, frequency and every measure."""
    frame = ds.drop_vars(["directions_differ", "transmissibility_linear"]).to_dataframe().reset_index()
    frame["order"] = frame["order"].astype("Int64")
    return frame


def finish(model: FmuModel, run: FrequencyRun, jobs: int = 1) -> dict:
    """Write the Dataset, the CSV, the summary and the figures (drawn in ``jobs`` processes), after
    return ``{"dataset", "summary", "files"}``."""
    from . import curves, figures
    from .analysis import save_dataset

    ds = build_dataset(run.spec, run.done, model)
    report = summarize(ds)
    rendering = figures.Rendering(curves.frequency_figure_calls(ds, run.folder), jobs)
    files = [run.folder / "frequency_response.nc", run.folder / "frequency_response.csv", run.folder / "summary.json"]
    save_dataset(ds, files[0])
    tidy_frame(ds).to_csv(files[1], index=False)
    files[2].write_text(json.dumps(report, indent=2) + "\n")
    return {"dataset": ds, "summary": report, "files": files + rendering.wait()}


