"""The figures of a random-excitation study:

- ``effectiveness.png``: the RMS ratio of the relative displacement (with over without the damper)
  against the RMS base acceleration, with its 95% interval, and the power harvested beside it: where
  the damper helps (below 1) and where it does not;
- ``psd.png``: the response PSD of the relative displacement with and without the damper, and the
  linear oscillator's ``|H|^2 G`` (the runs without the damper must follow it);
- ``history.png``: one realization's relative displacement with and without, over a stretch of the
  window, and its impacts;
- ``peaks.png``: the distribution of each realization's largest excursion, with and without, at
  every level (their medians and 95th percentiles marked).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...drawing import new_figure, save_png


def effectiveness(summary: dict, path: Path) -> Path:
    levels = [entry for entry in summary["levels"] if entry.get("base_acceleration_rms") is not None]
    fig, ax = new_figure((7.0, 4.4))
    if levels:
        x = np.array([entry["base_acceleration_rms"] for entry in levels])
        ratio = np.array([entry["ratio"] for entry in levels])
        low = np.array([entry["ratio_ci"][0] for entry in levels])
        high = np.array([entry["ratio_ci"][1] for entry in levels])
        if np.isfinite(low).all() and np.isfinite(high).all():
            ax.errorbar(x, ratio, yerr=[ratio - low, high - ratio], fmt="o-", color="C0", capsize=3, ms=6,
                        label="RMS ratio, relative displacement (95% interval)")
        else:  # one realization (a record): no interval to draw
            ax.plot(x, ratio, "o-", color="C0", ms=6, label="RMS ratio, relative displacement (one realization)")
        ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
        ax.set_xscale("log" if len(x) > 1 and x.max() / x.min() > 5 else "linear")
        power = ax.twinx()
        watts = np.array([entry["with"]["power"] for entry in levels])
        power.plot(x, watts * 1e3, "s--", color="C3", ms=5, label="harvested power (right)")
        power.set_ylabel("mean harvested power, both loads (mW)", color="C3")
        ax.set_ylim(0.0, max(1.1, float(np.max(np.where(np.isfinite(high), high, ratio))) * 1.05))
        handles = ax.get_legend_handles_labels()[0] + power.get_legend_handles_labels()[0]
        ax.legend(handles, [h.get_label() for h in handles], fontsize=8, loc="lower right")
    ax.set_xlabel("RMS base acceleration (m/s²)")
    ax.set_ylabel("RMS with the damper / without")
    ax.set_title("How much the damper takes away, and what it harvests", fontsize=10)
    return save_png(fig, path)


def spectra(frequencies, densities: dict, linear: dict, natural_hz: float, path: Path) -> Path:
    fig, ax = new_figure((7.0, 4.4))
    shown = frequencies > 0
    for (k, case), density in sorted(densities.items()):
        if k == 0:
            ax.loglog(frequencies[shown], density[shown], color="C0" if case == "with" else "C1", lw=1.2,
                      label=f"{case} the damper")
    if 0 in linear:
        ax.loglog(frequencies[shown], linear[0][shown], "k--", lw=0.8, label="linear oscillator, |H|² G")
    ax.axvline(natural_hz, color="0.6", lw=0.7, ls=":")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD of the relative displacement (m²/Hz)")
    ax.set_title("Response PSD at the first level (Welch)", fontsize=10)
    ax.legend(fontsize=8)
    return save_png(fig, path)


def history(trace_with: dict, trace_without: dict, start: float, span: float, path: Path) -> Path:
    fig, ax = new_figure((8.0, 4.0))
    t = trace_with["time"]
    shown = (t >= start) & (t <= start + span)
    for trace, color, label in ((trace_without, "C1", "without the damper"), (trace_with, "C0", "with the damper")):
        relative = trace["main_displacement"] - trace["base_displacement"]
        ax.plot(t[shown], relative[shown] * 1e3, color=color, lw=0.8, label=label)
    impacts = np.flatnonzero(np.diff(trace_with["impact_count"][shown]) > 0)
    if len(impacts):
        ax.plot(t[shown][impacts + 1], np.zeros(len(impacts)), "|", color="k", ms=6, label="impacts")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("displacement relative to the base (mm)")
    ax.set_title("One realization", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    return save_png(fig, path)


def peaks(levels: list, peak: np.ndarray, path: Path) -> Path:
    """``peak``: (level, realization, damper), m."""
    count = peak.shape[0]
    fig, axes = new_figure((4.0 * min(count, 3), 3.6), 1, min(count, 3), squeeze=False)
    for k, ax in enumerate(axes[0]):
        for d, (case, color) in enumerate((("with", "C0"), ("without", "C1"))):
            values = np.sort(peak[k, :, d][np.isfinite(peak[k, :, d])]) * 1e3
            if not len(values):
                continue
            ax.step(values, np.arange(1, len(values) + 1) / len(values), where="post", color=color, label=case)
            for q, style in ((0.5, "-"), (0.95, ":")):
                ax.axvline(float(np.quantile(values, q)), color=color, lw=0.7, ls=style)
        level = levels[k] if k < len(levels) else math.nan
        ax.set_title(f"level {level:.3g} (m/s²)²/Hz" if level == level else "the record", fontsize=9)
        ax.set_xlabel("largest relative excursion (mm)")
        ax.set_ylabel("share of the realizations at or below")
        ax.legend(fontsize=8, loc="lower right")
    return save_png(fig, path)
