"""A random-excitation study's results, from its chunks' records: the estimates at each level with their
95% intervals (:mod:`.statistics`), the response PSD, and the files.

Per level, with and without the damper: the RMS of the main mass's displacement relative to the base
and absolute (m), their ratio with over without (the relative one's is *the* ratio of the study,
paired over the realizations), the median and the 95th percentile of each realization's largest
relative excursion (m), the impacts a second, the mean power harvested in both loads (W) and the
RMS voltage of a patch (V, ``sqrt(R E / (2 T))`` with ``E`` the energy harvested in both loads over
the window ``T``), and the energy ledger's largest imbalance relative to the base's work.
"""

from __future__ import annotations

import math

import numpy as np

from ...random_response.march import DAMPERS, psd_length
from ...random_response.spec import RandomSpec
from ...random_response.statistics import mean_interval, paired_ratio, quantile_interval, rms_interval, welch_density

#: The per-realization measures kept in ``random.nc``, their units and descriptions.
MEASURES = {
    "rms_relative": ("m", "RMS over the window of the main mass's displacement relative to the base"),
    "rms_absolute": ("m", "RMS over the window of the main mass's absolute displacement"),
    "peak": ("m", "largest excursion of the displacement relative to the base in the window"),
    "impacts": ("1", "contact onsets in the window"),
    "power": ("W", "mean power into both loads over the window"),
    "balance": ("J", "base's work less the stored energy's change, the dissipation and the harvested energy"),
}


def arrays(spec: RandomSpec, done: dict) -> dict:
    """The measures as arrays ``(level, realization, damper)`` (NaN where a realization failed)."""
    levels = max(len(spec.levels), 1)
    out = {name: np.full((levels, spec.realizations, len(DAMPERS)), np.nan) for name in MEASURES}
    window = spec.duration
    for record in done.values():
        for row in record["realizations"]:
            r = row["realization"]
            for k, level in enumerate(row["levels"]):
                for d, case in enumerate(DAMPERS):
                    m = level[case]
                    value = (lambda x: math.nan if x is None else x)
                    out["rms_relative"][k, r, d] = math.sqrt(value(m["ms_relative"]))
                    out["rms_absolute"][k, r, d] = math.sqrt(value(m["ms_absolute"]))
                    out["peak"][k, r, d] = value(m["peak_relative"])
                    out["impacts"][k, r, d] = m["impacts"] if not m["failed"] else math.nan
                    out["power"][k, r, d] = value(m["harvested"]) / window
                    out["balance"][k, r, d] = value(m["balance"])
    return out


def summarize(spec: RandomSpec, done: dict, load: float) -> dict:
    """The estimates at each level (see the module's text), JSON-safe; ``load`` is ``R_load`` (Ohm)."""
    data = arrays(spec, done)
    works = {}
    for record in done.values():
        for row in record["realizations"]:
            for k, level in enumerate(row["levels"]):
                works.setdefault(k, []).append(abs(level["with"]["work"] or 0.0))
    levels = []
    for k in range(data["rms_relative"].shape[0]):
        ok = np.isfinite(data["rms_relative"][k]).all(axis=1)
        entry = {"level": spec.levels[k] if spec.levels else None, "realizations": int(ok.sum()),
                 "failed": int((~ok).sum())}
        ms = {case: data["rms_relative"][k, ok, d] ** 2 for d, case in enumerate(DAMPERS)}
        ratio, low, high = paired_ratio(ms["with"], ms["without"])
        entry.update(ratio=ratio, ratio_ci=[low, high])
        ms_abs = {case: data["rms_absolute"][k, ok, d] ** 2 for d, case in enumerate(DAMPERS)}
        entry["ratio_absolute"], *ci = paired_ratio(ms_abs["with"], ms_abs["without"])
        entry["ratio_absolute_ci"] = ci
        for d, case in enumerate(DAMPERS):
            rms, lo, hi = rms_interval(ms[case])
            rms_abs, lo_abs, hi_abs = rms_interval(ms_abs[case])
            median = quantile_interval(data["peak"][k, ok, d], 0.5)
            p95 = quantile_interval(data["peak"][k, ok, d], 0.95)
            impacts = mean_interval(data["impacts"][k, ok, d] / spec.duration)
            power = mean_interval(data["power"][k, ok, d])
            volts = rms_interval(load * data["power"][k, ok, d] / 2.0)
            entry[case] = {"rms_relative": rms, "rms_relative_ci": [lo, hi],
                           "rms_absolute": rms_abs, "rms_absolute_ci": [lo_abs, hi_abs],
                           "peak_median": median[0], "peak_median_ci": list(median[1:]),
                           "peak_p95": p95[0], "peak_p95_ci": list(p95[1:]),
                           "impacts_per_second": impacts[0], "impacts_per_second_ci": list(impacts[1:]),
                           "power": power[0], "power_ci": list(power[1:]),
                           "v_rms": volts[0], "v_rms_ci": list(volts[1:]),
                           "balance_max": float(np.nanmax(np.abs(data["balance"][k, :, d]))) if ok.any() else None}
        scale = max(works.get(k, [0.0]) or [0.0])
        entry["ledger_relative_max"] = entry["with"]["balance_max"] / scale if scale else None
        levels.append(entry)
    return {"levels": levels}


def psd(spec: RandomSpec, done: dict) -> tuple[np.ndarray, dict]:
    """The response PSD (m^2/Hz) of the relative displacement, by ``(level, damper)``, and its
    frequencies (Hz), from the chunks' Welch sums."""
    length = psd_length(spec)
    frequencies = np.fft.rfftfreq(length, spec.step)
    sums: dict = {}
    for record in done.values():
        for key, part in record["psd"].items():
            total = sums.setdefault(key, [np.zeros(len(frequencies)), 0])
            total[0] += np.asarray(part["sums"], float)
            total[1] += part["segments"]
    densities = {tuple((int(key.split(":")[0]), key.split(":")[1])): welch_density(s, n, spec.step, length)
                 for key, (s, n) in sums.items()}
    return frequencies, densities
