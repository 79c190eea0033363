"""Contour figures in the paper's units (mm, kg, cm/s, V, W): the sweeps' contours and Figs. 4-9
with the design zones outlined.

Matplotlib runs headless: figures are made without pyplot (``matplotlib.figure.Figure``, written
by the Agg canvas), so nothing is registered or left to close. Every function writes PNG files
and returns their paths; :class:`piezo_fmu_harness.drawing.Rendering` draws them in parallel.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from ...drawing import DPI

#: Parameter units shown in the paper's units: lengths in mm.
UNIT_DISPLAY = {"m": (1e3, "mm")}
#: Metrics: (factor, unit, label).
METRIC_DISPLAY = {
    "DI": (100.0, "cm/s", "Damping inclination DI"),
    "DI_ls": (100.0, "cm/s", "Robust damping inclination DI_ls"),
    "V_rms": (1.0, "V", "RMS output voltage $V_{rms}$"),
    "P_ave": (1.0, "W", "Average power $P_{ave}$"),
    "perfectibility": (1.0, "%", "Perfectibility"),
}
#: Which zone each paper figure outlines (Figs. 4-6 show the metric alone); "damping" is the
#: damping measure the sweep ranks by (DI, eq. 29, or DI_ls).
PAPER_FIGURES = {
    "fig4": ("damping", None), "fig5": ("V_rms", None), "fig6": ("P_ave", None),
    "fig7": ("damping", "damping"), "fig8": ("V_rms", "V_rms"), "fig9": ("perfectibility", "perfectibility"),
}
ZONE_TITLES = {"damping": "; vibratory-based zone", "V_rms": "; energy-based zone", "perfectibility": "; design zones"}


def axis_scale(units: str) -> tuple[float, str]:
    """Factor and unit to show a parameter in (metres as millimetres)."""
    return UNIT_DISPLAY.get(units, (1.0, units))


def display_value(name: str, value: float, units: str) -> str:
    factor, shown = axis_scale(units)
    return f"{name} = {value * factor:.4g} {shown}".rstrip()


def symbol(name: str) -> str:
    """A parameter name as the paper writes it, in TeX: x1 as $x_1$, C_eq as $C_{eq}$."""
    if "_" in name:
        head, tail = name.split("_", 1)
        return f"${head}_{{{tail}}}$"
    letters = name.rstrip("0123456789")
    if letters and letters != name:
        return f"${letters}_{{{name[len(letters):]}}}$"
    return f"${name}$"


def _axis_label(ds, name: str) -> str:
    factor, shown = axis_scale(ds[name].attrs.get("units", ""))
    return f"{symbol(name)} ({shown})" if shown and shown != "1" else symbol(name)


def _plot_axes(ds, metric: str) -> tuple[str, ...]:
    dims = ds[metric].dims
    if "x1" in dims and len(dims) == 2:
        return ("x1", dims[1] if dims[0] == "x1" else dims[0])  # x1 across, as in the paper
    return tuple(dims)


def draw_panel(ax, ds, metric: str, zone_mask: Optional[np.ndarray] = None,
               paper_zone: Optional[dict] = None, title: str = "") -> Optional[tuple]:
    """One contour panel of ``metric`` over a 2-D sweep (a line over a 1-D one), with our zone
    (solid red outline, best point starred) and the paper's design zone (dashed black). Returns
    the filled contours and the label of their colorbar, or ``None`` (a line, or no finite value)."""
    factor, unit, label = METRIC_DISPLAY.get(metric, (1.0, ds[metric].attrs.get("units", ""), metric))
    names = _plot_axes(ds, metric)
    if len(names) == 1:
        name = names[0]
        fx, _ = axis_scale(ds[name].attrs.get("units", ""))
        x, y = ds[name].values * fx, ds[metric].values * factor
        ax.plot(x, y, "o-", ms=3)
        if zone_mask is not None and zone_mask.any():
            ax.plot(x[zone_mask], y[zone_mask], "o", color="red", ms=5, label="our zone")
        if paper_zone and name in paper_zone:
            lo, hi = paper_zone[name]
            ax.axvspan(lo * fx, hi * fx, color="k", alpha=0.1, label="paper's design zone")
        ax.set_xlabel(_axis_label(ds, name))
        ax.set_ylabel(f"{label} ({unit})")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
        return None
    xname, yname = names
    data = ds[metric].transpose(yname, xname)
    fx, _ = axis_scale(ds[xname].attrs.get("units", ""))
    fy, _ = axis_scale(ds[yname].attrs.get("units", ""))
    x, y = ds[xname].values * fx, ds[yname].values * fy
    z = data.values * factor
    filled = None
    if np.isfinite(z).any():
        filled = ax.contourf(x, y, np.ma.masked_invalid(z), levels=20, cmap="viridis")
    if zone_mask is not None and zone_mask.any():
        dims = ds[metric].dims
        mask = zone_mask if dims == (yname, xname) else zone_mask.T
        ax.contour(x, y, mask.astype(float), levels=[0.5], colors="red", linewidths=1.5)
        best = np.unravel_index(np.nanargmax(np.where(mask, z, np.nan)), z.shape)
        ax.plot([], [], color="red", lw=1.5, label="our zone")
        ax.plot(x[best[1]], y[best[0]], ls="none", marker="*", color="red", ms=13, mec="white",
                clip_on=False, zorder=5, label="our best point")
    if paper_zone and (xname in paper_zone or yname in paper_zone):
        x0, x1 = (v * fx for v in paper_zone.get(xname, (ds[xname].values.min(), ds[xname].values.max())))
        y0, y1 = (v * fy for v in paper_zone.get(yname, (ds[yname].values.min(), ds[yname].values.max())))
        ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "k--", lw=1.5, label="paper's design zone")
    ax.set_xlabel(_axis_label(ds, xname))
    ax.set_ylabel(_axis_label(ds, yname))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="lower right", framealpha=0.8)
    ax.set_title(title, fontsize=9)
    return None if filled is None else (filled, f"{label} ({unit})")


def _subtitle(ds) -> str:
    import json

    fixed = json.loads(ds.attrs.get("fixed_parameters", "{}"))
    units = json.loads(ds.attrs.get("fixed_parameter_units", "{}"))
    shown = ", ".join(display_value(k, v, units.get(k, "")) for k, v in fixed.items())
    return f"{shown}{'; ' if shown else ''}{ds.attrs.get('stop_time_s', 0):g} s per run"


def _measure(ds, metric: str) -> str:
    from .analysis import damping_variable

    return damping_variable(ds) if metric == "damping" else metric


class ContourSheet:
    """A figure of ``count`` panels side by side, each with its colorbar axes, drawn again for every
    file: its axes, colorbars' axes and the metrics of its repeated texts are made once, a third of
    what a contour figure costs. Margins are fixed, in inches."""

    WIDTH, HEIGHT = 6.2, 4.8  # inches per panel, and the height

    def __init__(self, count: int):
        from matplotlib.figure import Figure

        self.figure = Figure(figsize=(self.WIDTH * count, self.HEIGHT))
        width, height = self.WIDTH * count, self.HEIGHT
        box = lambda left, w: [left / width, 0.55 / height, w / width, (height - 1.2) / height]  # noqa: E731
        self.axes = [self.figure.add_axes(box(self.WIDTH * k + 0.7, 4.15)) for k in range(count)]
        self.colorbar_axes = [self.figure.add_axes(box(self.WIDTH * k + 4.95, 0.14)) for k in range(count)]
        self.title = None

    def draw(self, panels: list[tuple], title: Optional[str], path: Path) -> Path:
        """Draw ``panels``, each ``(ds, metric, zone_mask, paper_zone, title)`` (:func:`draw_panel`),
        with the figure's ``title``, and write ``path``."""
        for k, (ax, panel) in enumerate(zip(self.axes, panels)):
            for artist in [*ax.collections, *ax.lines, *ax.patches]:
                artist.remove()
            if ax.get_legend() is not None:
                ax.get_legend().remove()
            ax.ignore_existing_data_limits = True  # the limits of this panel's data alone
            filled = draw_panel(ax, *panel[:4], title=panel[4])
            cax = self.colorbar_axes[k]
            cax.set_visible(filled is not None)
            if filled is not None:
                # A new colorbar in the same axes: Colorbar.update_normal keeps the old levels.
                cax.cla()
                self.figure.colorbar(filled[0], cax=cax, label=filled[1])
        if self.title is None:
            self.title = self.figure.suptitle("", fontsize=11)
        self.title.set_text(title or "")
        self.figure.savefig(path, dpi=DPI)
        return path


class Sheets:
    """The :class:`ContourSheet` of each panel count, made on first use: one set of calls shares
    it (in each process that draws them)."""

    def __init__(self):
        self._by_count: dict = {}

    def __getitem__(self, count: int) -> ContourSheet:
        if count not in self._by_count:
            self._by_count[count] = ContourSheet(count)
        return self._by_count[count]


def sweep_figure_calls(ds, zones: dict, paper_zone: Optional[dict], folder: Path, sheets: Sheets) -> list[tuple]:
    """``DI.png`` (or ``DI_ls.png``, the damping measure ranked by), ``V_rms.png``, ``P_ave.png``
    and ``perfectibility.png`` of one sweep, each with its own zone (P_ave shares V_rms's) and the
    paper's design zone, none beyond 2-D: as ``(function, *args)`` calls for :class:`Rendering`."""
    if len(ds["DI"].dims) > 2:
        return []
    measure = _measure(ds, "damping")
    return [(_sweep_figure, sheets, ds, metric, zones.get(zone_of), paper_zone, Path(folder) / f"{metric}.png")
            for metric, zone_of in ((measure, measure), ("V_rms", "V_rms"), ("P_ave", "V_rms"),
                                    ("perfectibility", "perfectibility"))]


def _sweep_figure(sheets: Sheets, ds, metric: str, zone: Optional[np.ndarray], paper_zone: Optional[dict],
                  path: Path) -> Path:
    title = f"{METRIC_DISPLAY[metric][2]}: sweep {ds.attrs.get('sweep')} ({_subtitle(ds)})"
    return sheets[1].draw([(ds, metric, zone, paper_zone, title)], None, path)


def damping_measures_figure(sheets: Sheets, ds, quantile: float, path: Path) -> Path:
    """Eq. 29's DI beside the robust DI_ls over one 2-D sweep, each with its own vibratory-based
    zone (the top ``quantile``) and the paper's design zone."""
    from .analysis import PAPER_ZONES, top_zone

    paper_zone = {name: PAPER_ZONES[name] for name in ds["DI"].dims if name in PAPER_ZONES} or None
    panels = [(ds, metric, top_zone(ds, metric, quantile)[0], paper_zone, f"{name}: {_subtitle(ds)}")
              for metric, name in (("DI", "(a) DI, eq. 29"), ("DI_ls", "(b) DI_ls, least-squares decay slope"))]
    return sheets[2].draw(panels, f"Damping measures over sweep {ds.attrs.get('sweep')}: vibratory-based zones "
                                  f"(top {100 * (1 - quantile):.0f}%)", path)


def paper_figure_calls(panels: dict, folder: Path, sheets: Sheets) -> list[tuple]:
    """Figs. 4-9, one file per figure, panel (a) the (x1, m) sweep and (b) the (x1, d) sweep, as
    ``(function, *args)`` calls for :class:`Rendering`; ``panels`` maps the panel letter to
    ``(dataset, zones, paper_zone)``."""
    return [(_paper_figure, sheets, panels, figure, metric, zone_of, Path(folder) / f"{figure}.png")
            for figure, (metric, zone_of) in PAPER_FIGURES.items()]


def _paper_figure(sheets: Sheets, panels: dict, figure: str, metric: str, zone_of: Optional[str],
                  path: Path) -> Path:
    drawn = []
    for letter, (ds, zones, paper_zone) in panels.items():
        shown = _measure(ds, metric)
        mask = zones.get(_measure(ds, zone_of)) if zone_of else None
        drawn.append((ds, shown, mask, paper_zone if zone_of in ("perfectibility", None) else None,
                      f"({letter}) {METRIC_DISPLAY[shown][2]}, {_subtitle(ds)}"))
    title = METRIC_DISPLAY[_measure(next(iter(panels.values()))[0], metric)][2]
    return sheets[len(panels)].draw(drawn, f"{figure.replace('fig', 'Fig. ')}: {title}"
                                           f"{ZONE_TITLES.get(zone_of or '', '')}", path)
