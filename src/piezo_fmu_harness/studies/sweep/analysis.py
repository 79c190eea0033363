"""From finished points to a sweep's results: the xarray Dataset, perfectibility (eq. 31) and
the design zones, saved as NetCDF, a tidy CSV and a JSON report.

Zones. The paper's design zones (Fig. 9) are ranges: ``m`` 0.17-0.20 kg, ``d`` 8-10 mm,
``x1`` 0-25 mm. Ours are found, not drawn: for a metric, the zone is the set of points at or
above the metric's ``quantile`` over the sweep (default 0.9, the top tenth), and its *region*
is the bounding box of the connected part of that set holding the best point. The metrics are
the paper's: ``DI`` gives the vibratory-based zone (Fig. 7), ``V_rms`` the energy-based zone
(Fig. 8), perfectibility the design zone (Fig. 9).

The damping measure. Eq. 29 takes the first two maxima of ``p``; an impact near a crest makes a
double maximum and a spike. ``--damping ls`` ranks by ``DI_ls`` instead, minus the least-squares
slope of the positive maxima that follow an impact (an FMU output): the vibratory-based zone and
perfectibility then use it. Eq. 29 stays the default.
"""

from __future__ import annotations

import json
from typing import Optional

import numpy as np

from ...fmu import METRIC_OUTPUTS, METRIC_UNITS, OPTIONAL_METRICS, FmuModel
from ...spec import SweepSpec
from ...wording import counted

#: The paper's design zones (SI): m 0.17-0.20 kg, d 8-10 mm, x1 0-25 mm (Fig. 9).
PAPER_ZONES = {"m": (0.17, 0.20), "d": (0.008, 0.010), "x1": (0.0, 0.025)}
#: Weight factors of eq. 31 (WF1 for V_rms, WF2 for DI).
WF1 = WF2 = 0.5
DEFAULT_ZONE_QUANTILE = 0.9
#: The damping measures (``--damping``) and the variable each ranks by.
DAMPING_MEASURES = {"eq29": "DI", "ls": "DI_ls"}
DEFAULT_DAMPING = "eq29"


def zone_kinds(ds) -> dict:
    """The zone of each metric, as the paper names them; the vibratory-based zone is the damping
    measure's the dataset was built with."""
    return {damping_variable(ds): "vibratory-based", "V_rms": "energy-based", "perfectibility": "design"}


def damping_variable(ds) -> str:
    """``DI`` (eq. 29) or ``DI_ls``: the damping measure the dataset ranks by."""
    return ds.attrs.get("damping_variable", "DI")


def perfectibility(v_rms: np.ndarray, di: np.ndarray) -> np.ndarray:
    """Eq. 31 over a sweep: ``100 (WF1 V_rms / max V_rms + WF2 DI / max DI)`` (%), maxima over
    the finished points of the sweep."""
    v_rms, di = np.asarray(v_rms, float), np.asarray(di, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return 100.0 * (WF1 * v_rms / np.nanmax(v_rms) + WF2 * di / np.nanmax(di))


def build_dataset(spec: SweepSpec, records: dict[int, dict], model: FmuModel, damping: str = DEFAULT_DAMPING):
    """The sweep as an ``xarray.Dataset`` over its axes, with perfectibility by the damping
    measure ``damping`` (:data:`DAMPING_MEASURES`); points not finished or rejected by the FMU
    are NaN (their ``status`` says which)."""
    import xarray as xr

    shape, dims = spec.shape, [axis.name for axis in spec.axes]
    keys = list(METRIC_OUTPUTS) + [key for key in OPTIONAL_METRICS
                                   if any(key in record for record in records.values())]
    measure = DAMPING_MEASURES[damping]
    if measure not in keys:
        raise ValueError(f"the points carry no {measure} (an FMU older than its output "
                         f"{OPTIONAL_METRICS.get(measure, measure)})")
    metrics = {key: np.full(shape, np.nan) for key in keys}
    seconds = np.full(shape, np.nan)
    cpu_seconds = np.full(shape, np.nan)
    status = np.full(shape, "missing", dtype=object)
    error = np.full(shape, "", dtype=object)
    for index, record in records.items():
        position = np.unravel_index(index, shape)
        for key in keys:
            value = record.get(key)
            metrics[key][position] = np.nan if value is None else value
        seconds[position] = record.get("seconds", np.nan)
        cpu_seconds[position] = record.get("cpu_seconds", np.nan)
        status[position] = record["status"]
        error[position] = record.get("error") or ""

    coords = {}
    for axis in spec.axes:
        parameter = model.parameters[axis.name]
        coords[axis.name] = (axis.name, np.asarray(axis.values),
                             {"units": parameter.unit or "1", "long_name": parameter.description})
    outputs = {**METRIC_OUTPUTS, **OPTIONAL_METRICS}
    data = {key: (dims, values, {"units": METRIC_UNITS[key], "fmu_output": outputs[key]})
            for key, values in metrics.items()}
    data["DI"][2]["long_name"] = "damping inclination (eq. 29)"
    if "DI_ls" in data:
        data["DI_ls"][2]["long_name"] = "robust damping inclination: least-squares decay slope of the maxima"
    data["V_rms"][2]["long_name"] = "RMS of the impact voltages (eq. 30)"
    data["P_ave"][2]["long_name"] = "average power V_rms^2 / R_load (eq. 30)"
    data["perfectibility"] = (dims, perfectibility(metrics["V_rms"], metrics[measure]),
                              {"units": "%", "long_name": f"perfectibility (eq. 31, WF1 = {WF1}, WF2 = {WF2}, "
                                                          f"damping measure {measure})"})
    data["status"] = (dims, status.astype(str), {"long_name": "ok, error (the FMU rejected the point) or missing"})
    data["error"] = (dims, error.astype(str), {"long_name": "the FMU's message for a rejected point"})
    data["seconds"] = (dims, seconds, {"units": "s", "long_name": "wall time of the point in its worker"})
    data["cpu_seconds"] = (dims, cpu_seconds, {"units": "s", "long_name": "CPU time of the point in its worker"})
    fixed = {name: value for name, value in spec.fixed.items()}
    attrs = {
        "title": f"piezo-impact damper sweep {spec.name}",
        "sweep": spec.name,
        "stop_time_s": spec.stop_time,
        "communication_step_s": spec.step,
        "fixed_parameters": json.dumps(fixed),
        "fixed_parameter_units": json.dumps({name: model.parameters[name].unit or "" for name in fixed}),
        "parameters_not_listed": "the FMU's start values (the nominal case)",
        "fmu": str(model.path),
        "fmu_guid": model.guid,
        "units": "SI (DI in m/s; multiply by 100 for the paper's cm/s)",
        "damping_variable": measure,
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def paper_zone_mask(ds) -> Optional[np.ndarray]:
    """Points inside the paper's ranges for every swept axis that has one; ``None`` if none has."""
    axes = [name for name in ds["DI"].dims if name in PAPER_ZONES]
    if not axes:
        return None
    mask = np.ones(ds["DI"].shape, dtype=bool)
    for name in axes:
        lo, hi = PAPER_ZONES[name]
        tol = 1e-9 * max(abs(lo), abs(hi), 1e-12)
        inside = (ds[name].values >= lo - tol) & (ds[name].values <= hi + tol)
        shape = [1] * mask.ndim
        shape[ds["DI"].dims.index(name)] = -1
        mask &= inside.reshape(shape)
    return mask


def top_zone(ds, metric: str, quantile: float = DEFAULT_ZONE_QUANTILE) -> tuple[np.ndarray, dict]:
    """The top-``quantile`` zone of ``metric``: its mask and a JSON-safe description."""
    values = ds[metric].values
    finite = np.isfinite(values)
    if not finite.any():
        return np.zeros(values.shape, bool), {"metric": metric, "points": 0}
    threshold = float(np.quantile(values[finite], quantile))
    mask = finite & (values >= threshold)
    labels, count = connected_parts(mask)
    best = np.unravel_index(np.nanargmax(values), values.shape)
    region_mask = labels == labels[best]
    dims = ds[metric].dims
    report = {
        "metric": metric,
        "kind": zone_kinds(ds).get(metric, ""),
        "quantile": quantile,
        "threshold": threshold,
        "units": ds[metric].attrs.get("units", ""),
        "points": int(mask.sum()),
        "of_points": int(finite.sum()),
        "connected_parts": int(count),
        "best": {**{name: float(ds[name].values[best[k]]) for k, name in enumerate(dims)},
                 metric: float(values[best])},
        "region": {},  # bounding box of the connected part holding the best point
        "extent": {},  # bounding box of every point in the zone
    }
    for k, name in enumerate(dims):
        coord = ds[name].values
        for key, which in (("region", region_mask), ("extent", mask)):
            index = np.nonzero(which.any(axis=tuple(j for j in range(values.ndim) if j != k)))[0]
            report[key][name] = [float(coord[index.min()]), float(coord[index.max()])]
    return mask, report


def connected_parts(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """The connected parts of ``mask``, points touching by a face, an edge or a corner: labels
    1..count (0 outside) and count, as ``scipy.ndimage.label`` with a full 3^n structure (whose
    import cost a third of a second after a sweep). A walk over the masked points only."""
    import itertools

    inside = {tuple(int(i) for i in point) for point in zip(*np.nonzero(mask))}
    steps = [step for step in itertools.product((-1, 0, 1), repeat=mask.ndim) if any(step)]
    labels = np.zeros(mask.shape, dtype=int)
    count = 0
    for start in sorted(inside):  # C order, as scipy numbers its parts
        if labels[start]:
            continue
        count += 1
        labels[start] = count
        stack = [start]
        while stack:
            point = stack.pop()
            for step in steps:
                near = tuple(p + d for p, d in zip(point, step))
                if near in inside and not labels[near]:
                    labels[near] = count
                    stack.append(near)
    return labels, count


def zones_report(ds, quantile: float = DEFAULT_ZONE_QUANTILE) -> dict:
    """Our zones (DI, V_rms, perfectibility) and how the paper's design zone fares in this sweep."""
    report = {"sweep": ds.attrs.get("sweep"), "stop_time_s": ds.attrs.get("stop_time_s"),
              "damping_measure": damping_variable(ds), "zones": {}, "paper": None}
    masks = {}
    for metric in zone_kinds(ds):
        masks[metric], report["zones"][metric] = top_zone(ds, metric, quantile)
    paper = paper_zone_mask(ds)
    if paper is not None:
        perf = ds["perfectibility"].values
        finite = np.isfinite(perf)
        design = masks["perfectibility"]
        inside = paper & finite
        report["paper"] = {
            "ranges": {name: list(PAPER_ZONES[name]) for name in ds["DI"].dims if name in PAPER_ZONES},
            "points": int(paper.sum()),
            "mean_perfectibility_inside": _mean(perf[inside]),
            "mean_perfectibility_sweep": _mean(perf[finite]),
            "share_of_paper_zone_in_our_design_zone": _ratio((paper & design).sum(), paper.sum()),
            "share_of_our_design_zone_in_paper_zone": _ratio((paper & design).sum(), design.sum()),
            "best_point_in_paper_zone": bool(paper[np.unravel_index(np.nanargmax(perf), perf.shape)])
            if finite.any() else None,
        }
    return report


def _mean(values: np.ndarray) -> Optional[float]:
    return float(np.mean(values)) if values.size else None


def _ratio(a, b) -> Optional[float]:
    return float(a) / float(b) if b else None


def tidy_frame(ds, quantile: float = DEFAULT_ZONE_QUANTILE):
    """One row per point: the axes, the metrics (DI also in cm/s), perfectibility, status and
    whether the point lies in the paper's design zone and in ours."""
    frame = ds.to_dataframe().reset_index()
    frame.insert(0, "index", np.arange(len(frame)))
    for key in ("DI", "DI_ls"):
        if key in frame:
            frame.insert(frame.columns.get_loc(key) + 1, f"{key}_cm_per_s", 100.0 * frame[key])
    paper = paper_zone_mask(ds)
    if paper is not None:
        frame["in_paper_design_zone"] = paper.reshape(-1)
    frame["in_our_design_zone"] = top_zone(ds, "perfectibility", quantile)[0].reshape(-1)
    frame["impact_count"] = frame["impact_count"].astype("Int64")  # whole numbers, blank if missing
    return frame


def zone_summary_lines(report: dict, show) -> list[str]:
    """Human-readable lines for a zones report; ``show(name, lo, hi=None)`` formats a value or
    a range in display units."""
    lines = [f"sweep {report['sweep']} ({report['stop_time_s']:g} s per run):"]
    for metric, zone in report["zones"].items():
        if not zone.get("points"):
            continue
        region = ", ".join(show(name, lo, hi) for name, (lo, hi) in zone["region"].items())
        best = ", ".join(show(name, value) for name, value in zone["best"].items())
        lines.append(f"  {zone['kind']} zone (top {100 * (1 - zone['quantile']):.0f}% of {metric}: "
                     f"{counted(zone['points'], 'point')}, {counted(zone['connected_parts'], 'connected part')}): "
                     "around the best "
                     f"point {region}; best {best}")
    paper = report.get("paper")
    if paper:
        ranges = ", ".join(show(name, lo, hi) for name, (lo, hi) in paper["ranges"].items())
        share = paper["share_of_paper_zone_in_our_design_zone"]
        lines.append(f"  paper's design zone {ranges}: {counted(paper['points'], 'point')}, mean perfectibility "
                     f"{_fmt(paper['mean_perfectibility_inside'])} % there vs {_fmt(paper['mean_perfectibility_sweep'])} % "
                     f"over the sweep; {_fmt(None if share is None else 100 * share)} % of it lies in our design zone")
    return lines


def _fmt(value: Optional[float]) -> str:
    return "n/a" if value is None else f"{value:.1f}"
