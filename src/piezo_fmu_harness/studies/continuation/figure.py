"""``continuation.png``: the branches of periodic orbits over the sweeps' points.

Stable parts of a branch are drawn solid and unstable parts dashed, in the branch's colour; the
up and down sweeps that gave the seeds are drawn as in the frequency response (stable orbits
filled, motions that are not periodic hollow); the bifurcations are marked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import FREQUENCY, new_figure, save_png
from ...wording import counted

#: Markers of the bifurcations.
EVENT_STYLES = {
    "fold": dict(marker="o", color="k", label="fold (multiplier +1)"),
    "period doubling": dict(marker="s", color="C3", label="period doubling (-1)"),
    "Neimark-Sacker": dict(marker="D", color="C4", label="Neimark-Sacker (complex pair)"),
    "branch point": dict(marker="*", color="C5", label="branch point (+1, no turn)"),
    "grazing": dict(marker="x", color="C2", label="grazing (end of the smooth branch)"),
}
SWEEP_STYLES = {"up": dict(marker="^", color="C0"), "down": dict(marker="v", color="C3")}


def draw(ds, chains: list[dict], path: Path) -> Path:
    fig, ax = new_figure((7.5, 4.8))
    lam, amplitude = ds["lam"].values, ds["amplitude"].values * 1e3
    for index in np.unique(ds["branch"].values):
        rows = np.flatnonzero(ds["branch"].values == index)
        stable = ds["stable"].values[rows] == 1
        for k in range(len(rows) - 1):
            both = stable[k] and stable[k + 1]
            ax.plot(lam[rows[k:k + 2]], amplitude[rows[k:k + 2]], color="0.15" if both else "0.45",
                    ls="-" if both else "--", lw=1.6 if both else 0.9)
    for chain in chains:
        style = SWEEP_STYLES[chain["direction"]]
        for settled, fill in ((True, style["color"]), (False, "none")):
            chosen = [r for r in chain["records"] if r.get("status") == "ok" and bool(r.get("settled")) == settled]
            if chosen:
                ax.plot([r["lam"] for r in chosen], [1e3 * r["amplitude"] for r in chosen], ls="none",
                        marker=style["marker"], ms=4.5, mfc=fill, color=style["color"], alpha=0.8,
                        label=f"sweep {chain['direction']}, {'stable orbit' if settled else 'undecided'}")
    for kind, style in EVENT_STYLES.items():
        where = ds["event_kind"].values == kind
        if where.any():
            ax.plot(ds["event_lam"].values[where], ds["event_amplitude"].values[where] * 1e3, ls="none", ms=7,
                    mfc="none", mew=1.4, **style)
    ax.plot([], [], color="0.15", lw=1.6, label="branch, stable")
    ax.plot([], [], color="0.45", ls="--", lw=0.9, label="branch, unstable")
    ax.set_yscale("log")
    parameter = ds.attrs["parameter"]
    ax.set_xlabel(FREQUENCY if parameter == "ratio" else f"{parameter} (SI)")
    ax.set_ylabel("main mass amplitude (mm), half peak-to-peak")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6.5, ncol=2)
    ax.set_title(f"Continuation: {counted(len(np.unique(ds['branch'].values)), 'branch')} of periodic orbits", fontsize=9)
    return save_png(fig, path)
