"""``bifurcation.png``: the section samples of ``p`` against the frequency ratio, up and down, and
the impacts per cycle beneath."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import FREQUENCY, new_figure, save_png

def scale_of(samples_mm: np.ndarray) -> float:
    """Where the symmetric log scale of the samples (mm) turns linear: the power of ten at or below
    the smallest quarter of their sizes, so that the ticks fall at the data's scale."""
    sizes = np.abs(samples_mm[np.isfinite(samples_mm)])
    sizes = sizes[sizes > 0]
    if not sizes.size:
        return 1.0
    return float(10.0 ** np.floor(np.log10(np.quantile(sizes, 0.25))))


STYLES = {"up": dict(color="C0", label="sweep up"), "down": dict(color="C3", label="sweep down")}


def draw(ds, path: Path) -> Path:
    from matplotlib.ticker import FuncFormatter, SymmetricalLogLocator

    fig, (top, bottom) = new_figure((7.5, 6.2), 2, 1, sharex=True, gridspec_kw={"height_ratios": (3, 1)})
    ratio = ds["ratio"].values
    for j, direction in enumerate(ds["direction"].values):
        samples = ds["p_section"].values[j] * 1e3
        x = np.repeat(ratio[:, None], samples.shape[1], axis=1)
        top.plot(x.ravel(), samples.ravel(), ls="none", marker="o", ms=2.4, mew=0, alpha=0.75, **STYLES[str(direction)])
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
    linear = scale_of(ds["p_section"].values * 1e3)
    top.set_yscale("symlog", linthresh=linear)  # tenths of a millimetre to the 100 mm of the chatter resonance
    top.yaxis.set_major_locator(SymmetricalLogLocator(linthresh=linear, base=10))
    top.yaxis.set_minor_locator(SymmetricalLogLocator(linthresh=linear, base=10, subs=np.arange(2, 10)))
    top.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    top.set_ylabel(f"p at the section (mm; linear within {linear:g} mm)")
    top.legend(fontsize=7, markerscale=3)
    top.grid(alpha=0.3)
    top.set_title("Bifurcation diagram: Poincare samples of p after the transients", fontsize=9)
    bottom.set_ylabel("impacts / cycle")
    bottom.set_xlabel(FREQUENCY)
    bottom.grid(alpha=0.3)
    return save_png(fig, path)
