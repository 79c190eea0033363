"""``fractions.png``: the share of each attractor stacked over frequency (one stacked bar for a study
of one frequency), and each attractor's amplitude."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import FREQUENCY, new_figure, save_png


def frequency_limits(ratio: np.ndarray) -> tuple[float, float]:
    """The frequency axis's limits: the band, or a little either side of one frequency."""
    lo, hi = float(ratio.min()), float(ratio.max())
    return (lo, hi) if hi > lo else (lo - 0.05 * lo, hi + 0.05 * hi)


def draw(ds, path: Path) -> Path:
    fig, (top, bottom) = new_figure((7.5, 7.5), 2, 1)
    ratio = ds["ratio"].values
    names = [str(n) for n in ds["attractor_name"].values]
    from matplotlib import colormaps

    palette = colormaps["tab20"]
    colors = [palette(k % 20) for k in range(len(names))]
    fractions = 100 * ds["fraction"].values.T
    limits = frequency_limits(ratio)
    if len(ratio) > 1:
        top.stackplot(ratio, fractions, labels=names, colors=colors, alpha=0.85)
    else:  # one frequency: its shares as one stacked bar
        width = 0.3 * (limits[1] - limits[0])
        below = np.cumsum(np.vstack([np.zeros((1, 1)), fractions[:-1]]), axis=0)
        for k, name in enumerate(names):
            top.bar(ratio, fractions[k], width, bottom=below[k], color=colors[k], alpha=0.85, label=name)
    top.set_ylabel("share of the starts (%)")
    top.set_ylim(0, 100)
    top.set_xlim(*limits)
    top.set_title(f"Where {ds.attrs['starts_per_frequency']} random starts go, at each frequency", fontsize=9)
    top.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    for k, name in enumerate(names):
        # NaN where the attractor is absent: the line breaks there instead of joining distant points
        amplitude = np.where(ds["fraction"].values[:, k] > 0, ds["amplitude"].values[:, k], np.nan)
        if np.isfinite(amplitude).any():
            bottom.semilogy(ratio, 1e3 * amplitude, "o-", ms=4, color=colors[k], label=name)
    bottom.set_xlabel(FREQUENCY)
    bottom.set_ylabel("amplitude of the main mass (mm)")
    bottom.set_xlim(*limits)
    return save_png(fig, path)
