"""``bifurcation.png``: the section samples of ``p`` against the frequency ratio, up and down, and
the impacts per cycle beneath."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import new_figure, save_png

STYLES = {"up": dict(color="C0", label="sweep up"), "down": dict(color="C3", label="sweep down")}


def draw(ds, path: Path) -> Path:
    fig, (top, bottom) = new_figure((7.5, 6.2), 2, 1, sharex=True, gridspec_kw={"height_ratios": (3, 1)})
    ratio = ds["ratio"].values
    for j, direction in enumerate(ds["direction"].values):
        samples = ds["p_section"].values[j] * 1e3
        x = np.repeat(ratio[:, None], samples.shape[1], axis=1)
        top.plot(x.ravel(), samples.ravel(), ls="none", marker=".", ms=2.6, mew=0, **STYLES[str(direction)])
        bottom.plot(ratio, ds["impacts_per_cycle"].values[j], ls="-", lw=0.9, marker=".", ms=2, **STYLES[str(direction)])
    motion = ds["motion"].values.astype(str)
    chaotic = (motion == "chaotic").any(axis=0)
    modulated = (motion == "quasi-periodic").any(axis=0)
    undecided = np.char.startswith(motion, "undecided").any(axis=0)
    half = 0.5 * (ratio[-1] - ratio[0]) / max(1, len(ratio) - 1)
    for mask, color, label in ((chaotic, "C1", "chaotic, shown to persist (one sweep or both)"),
                               (modulated, "C2", "quasi-periodic, shown to persist"),
                               (undecided, "0.6", "undecided within the budget")):
        for k in np.flatnonzero(mask):
            top.axvspan(ratio[k] - half, ratio[k] + half, color=color, alpha=0.12, lw=0)
        if mask.any():
            top.axvspan(np.nan, np.nan, color=color, alpha=0.12, label=label)
    top.set_yscale("symlog", linthresh=2.0)  # millimetres of the orbits and the 100 mm of the chatter resonance
    top.set_ylabel("p at the section (mm, linear within 2 mm)")
    top.legend(fontsize=7, markerscale=5)
    top.grid(alpha=0.3)
    top.set_title("Bifurcation diagram: Poincare samples of p after the transients", fontsize=9)
    bottom.set_ylabel("impacts / cycle")
    bottom.set_xlabel(r"frequency ratio $\omega / \sqrt{K/M}$")
    bottom.grid(alpha=0.3)
    return save_png(fig, path)
