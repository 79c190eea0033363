"""``fractions.png``: the share of each attractor stacked over frequency, and each attractor's
amplitude."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import new_figure, save_png


def draw(ds, path: Path) -> Path:
    fig, (top, bottom) = new_figure((7.5, 7.5), 2, 1)
    ratio = ds["ratio"].values
    names = [str(n) for n in ds["attractor_name"].values]
    from matplotlib import colormaps

    palette = colormaps["tab20"]
    colors = [palette(k % 20) for k in range(len(names))]
    fractions = ds["fraction"].values.T
    top.stackplot(ratio, 100 * fractions, labels=names, colors=colors, alpha=0.85)
    top.set_ylabel("share of the starts (%)")
    top.set_ylim(0, 100)
    top.set_xlim(ratio.min(), ratio.max())
    top.set_title(f"Where {ds.attrs['starts_per_frequency']} random starts go, at each frequency", fontsize=9)
    top.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    for k, name in enumerate(names):
        # NaN where the attractor is absent: the line breaks there instead of joining distant points
        amplitude = np.where(ds["fraction"].values[:, k] > 0, ds["amplitude"].values[:, k], np.nan)
        if np.isfinite(amplitude).any():
            bottom.semilogy(ratio, 1e3 * amplitude, "o-", ms=3, color=colors[k], label=name)
    bottom.set_xlabel("w / sqrt(K/M)")
    bottom.set_ylabel("amplitude of the main mass (mm)")
    bottom.set_xlim(ratio.min(), ratio.max())
    return save_png(fig, path)
