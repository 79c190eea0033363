"""``basins.png``: the attractor each start ends on, over the grid of starts, and beside it the
transient's length: the periods each start took to reach its motion (the budget where it
was left undecided), on a log scale: where the machine settles fast and where it rattles first."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import RATIO, new_figure, save_png


def draw(ds, path: Path) -> Path:
    from matplotlib.colors import ListedColormap

    from matplotlib.colors import LogNorm

    fig, (ax, right) = new_figure((11.0, 5.6), 1, 2)
    count = ds.sizes["attractor"]
    colors = [f"C{k % 10}" for k in range(count)]
    ax.pcolormesh(ds["dp0"].values, ds["p0"].values * 1e3, ds["basin"].values, cmap=ListedColormap(colors),
                  vmin=-0.5, vmax=count - 0.5, shading="nearest")
    for k in range(count):
        ax.plot([], [], "s", color=colors[k], ms=8,
                label=f"{ds['attractor_name'].values[k]}: {100 * ds['attractor_share'].values[k]:.1f}% "
                      f"({100 * ds['share_low'].values[k]:.1f}-{100 * ds['share_high'].values[k]:.1f}%)")
    ax.set_xlabel("initial velocity of the main mass p0' (m/s)")
    ax.set_ylabel("initial displacement p0 (mm)")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    ax.set_title(f"Basins of attraction at {RATIO} = {ds.attrs['ratio']:g} (impact mass at rest in the middle)", fontsize=9)
    periods = np.maximum(ds["periods"].values.astype(float), 1.0)  # a start labelled at once: drawn as 1
    mesh = right.pcolormesh(ds["dp0"].values, ds["p0"].values * 1e3, periods, shading="nearest", cmap="magma_r",
                            norm=LogNorm(vmin=1.0, vmax=max(2.0, float(periods.max()))))
    fig.colorbar(mesh, ax=right, label="periods to reach the motion (1: at once; the budget: undecided)")
    right.set_xlabel("initial velocity of the main mass p0' (m/s)")
    right.set_title(f"How long the transient lasts (budget {ds.attrs.get('budget_periods', '?')} periods)", fontsize=9)
    return save_png(fig, path)
