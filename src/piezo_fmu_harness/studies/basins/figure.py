"""``basins.png``: the attractor each start ends on, over the grid of starts."""

from __future__ import annotations

from pathlib import Path

from ...drawing import new_figure, save_png


def draw(ds, path: Path) -> Path:
    from matplotlib.colors import ListedColormap

    fig, ax = new_figure((7.0, 5.4))
    count = ds.sizes["attractor"]
    colors = [f"C{k % 10}" for k in range(count)]
    ax.pcolormesh(ds["dp0"].values, ds["p0"].values * 1e3, ds["attractor"].values, cmap=ListedColormap(colors),
                  vmin=-0.5, vmax=count - 0.5, shading="nearest")
    for k in range(count):
        ax.plot([], [], "s", color=colors[k], ms=8,
                label=f"{ds['attractor_name'].values[k]}: {100 * ds['attractor_share'].values[k]:.1f}% "
                      f"({100 * ds['share_low'].values[k]:.1f}-{100 * ds['share_high'].values[k]:.1f}%)")
    ax.set_xlabel("initial velocity of the main mass p0' (m/s)")
    ax.set_ylabel("initial displacement p0 (mm)")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    ax.set_title(f"Basins of attraction at w/w_n = {ds.attrs['ratio']:g} (impact mass at rest in the middle)", fontsize=9)
    return save_png(fig, path)
