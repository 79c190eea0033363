"""The frequency response's figures: amplitude, harvested power and impacts per cycle against
the frequency ratio."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import FREQUENCY, new_figure, save_png


#: Line styles of the frequency-response figures, by (damper, direction).
FREQUENCY_STYLES = {
    ("with", "up"): dict(color="C0", marker="^", ls="-", label="with damper, sweep up"),
    ("with", "down"): dict(color="C3", marker="v", ls="--", label="with damper, sweep down"),
    ("without", "up"): dict(color="0.45", marker="", ls="-", label="without damper, sweep up"),
    ("without", "down"): dict(color="0.45", marker="o", ls="none", label="without damper, sweep down"),
}


def frequency_figure_calls(ds, folder: Path) -> list[tuple]:
    """``amplitude.png`` (with and without the damper, up and down, the closed form without it),
    ``power.png`` (harvested power) and ``impacts.png`` (impacts per forcing cycle), against the
    frequency ratio, as calls for :class:`piezo_fmu_harness.drawing.Rendering`; bands where the two directions differ are
    shaded, the stable orbits are joined by lines, motions that are not periodic are drawn hollow
    (with their amplitude envelope), and the unstable orbits met are grey crosses."""
    panels = (
        ("amplitude", 1e3, "main mass amplitude (mm), half peak-to-peak", ("with", "without"), "amplitude.png"),
        ("harvested_power", 1e3, "harvested power, both loads (mW)", ("with",), "power.png"),
        ("impacts_per_cycle", 1.0, "impacts per forcing cycle", ("with",), "impacts.png"),
    )
    return [(_frequency_figure, ds, *panel[:4], Path(folder) / panel[4]) for panel in panels]


def _frequency_figure(ds, key: str, factor: float, label: str, cases: tuple, path: Path) -> Path:
    from ...datasets import bands

    ratio = ds["ratio"].values
    half_step = 0.5 * (ratio[-1] - ratio[0]) / max(1, len(ratio) - 1)
    fig, ax = new_figure((7.5, 4.6))
    differ = ds["directions_differ"].sel(damper="with").values == 1
    for lo, hi in bands(ratio, differ):
        ax.axvspan(lo - half_step, hi + half_step, color="C1", alpha=0.15, lw=0)
    for damper in cases:
        for direction in ("up", "down"):
            style = FREQUENCY_STYLES[damper, direction]
            y = ds[key].sel(damper=damper, direction=direction).values * factor
            settled = ds["settled"].sel(damper=damper, direction=direction).values == 1
            ax.plot(ratio, np.where(settled, y, np.nan), ls=style["ls"], color=style["color"], lw=1.2,
                    marker=style["marker"], ms=4, label=style["label"])
            loose = ds["verdict"].sel(damper=damper, direction=direction).values == "undecided"
            if loose.any():
                ax.plot(ratio[loose], y[loose], ls="none", marker=style["marker"] or "o", ms=6,
                        mfc="none", color=style["color"])
                if key == "amplitude":  # the envelope of the motion over its window
                    low = ds["amplitude_min"].sel(damper=damper, direction=direction).values[loose] * factor
                    high = ds["amplitude_max"].sel(damper=damper, direction=direction).values[loose] * factor
                    ax.vlines(ratio[loose], low, high, color=style["color"], lw=0.8)
        unstable = ds["unstable_damper"].values == damper
        if unstable.any() and f"unstable_{key}" in ds:
            ax.plot(ds["unstable_ratio"].values[unstable], ds[f"unstable_{key}"].values[unstable] * factor,
                    ls="none", marker="x", ms=4, color="0.55", mew=0.8)
    if key == "amplitude":
        linear = ds["transmissibility_linear"].values * ds["base_amplitude"].values * factor
        ax.plot(ratio, linear, color="k", ls=":", lw=1.0, label="without damper, closed form")
        ax.set_yscale("log")
    elif key == "harvested_power":
        ax.set_yscale("symlog", linthresh=1e-2)  # zero where nothing impacts, decades where it does
    if differ.any():
        ax.axvspan(np.nan, np.nan, color="C1", alpha=0.15, label="up and down differ (with damper)")
    ax.plot([], [], ls="none", marker="o", mfc="none", color="0.3", label="undecided within the cap (hollow; bar: envelope)")
    if ds.sizes.get("unstable", 0):
        ax.plot([], [], ls="none", marker="x", ms=4, color="0.55", mew=0.8, label="unstable orbit met (never the response)")
    ax.set_xlabel(FREQUENCY)
    ax.set_ylabel(label)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(f"Frequency response: {ds.attrs['excitation']}", fontsize=9)
    return save_png(fig, path)
