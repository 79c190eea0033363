"""Figures in the paper's units (mm, kg, cm/s, V, W): Fig. 3 (nominal case), the sweep
contours of Figs. 4-9 with the design zones outlined, and Fig. 10 (two designs).

Matplotlib runs headless: figures are made without pyplot (``matplotlib.figure.Figure``, written
by the Agg canvas), so nothing is registered or left to close. Every function writes PNG files
and returns their paths.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

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



#: Resolution of every PNG.
DPI = 130


def _figure(figsize: tuple, *grid, **kwargs):
    """A new figure and its axes (``Figure.subplots(*grid, **kwargs)``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, **kwargs)


def _save(fig, path: Path, layout: bool = True) -> Path:
    """Lay out ``fig`` (unless its layout is fixed already), write it to ``path`` (PNG); return
    ``path``."""
    if layout:
        fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


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


def sweep_figures(ds, zones: dict, paper_zone: Optional[dict], folder: Path) -> list[Path]:
    """``DI.png`` (or ``DI_ls.png``, the damping measure ranked by), ``V_rms.png``, ``P_ave.png``
    and ``perfectibility.png`` of one sweep, each with its own zone (P_ave shares V_rms's) and the
    paper's design zone; none beyond 2-D."""
    return render(sweep_figure_calls(ds, zones, paper_zone, folder, Sheets()))


def sweep_figure_calls(ds, zones: dict, paper_zone: Optional[dict], folder: Path, sheets: Sheets) -> list[tuple]:
    """The figures of :func:`sweep_figures` as ``(function, *args)`` calls, to be run anywhere."""
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


def paper_figures(panels: dict, folder: Path) -> list[Path]:
    """Figs. 4-9: one file per figure, panel (a) the (x1, m) sweep and (b) the (x1, d) sweep.

    ``panels`` maps the panel letter to ``(dataset, zones, paper_zone)``."""
    return render(paper_figure_calls(panels, folder, Sheets()))


def paper_figure_calls(panels: dict, folder: Path, sheets: Sheets) -> list[tuple]:
    """The figures of :func:`paper_figures` as ``(function, *args)`` calls, to be run anywhere."""
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


class Rendering:
    """Figure calls (``(function, *args)``, each returning the path it wrote, its last argument)
    being drawn: in ``jobs`` forked processes where the platform forks, while this process does
    something else, or here at :meth:`wait`.

    A forked child copies only the thread that forked; it draws with matplotlib (imported, with
    its fonts loaded, before the fork: nothing is imported or pickled again) and writes its files,
    which no other thread of this process does, so it needs no lock another thread may hold."""

    def __init__(self, calls: list[tuple], jobs: int = 1):
        import multiprocessing

        self.calls = calls
        self.children = []
        jobs = min(jobs, len(calls))
        if jobs >= 2 and "fork" in multiprocessing.get_all_start_methods():
            context = multiprocessing.get_context("fork")
            self.children = [context.Process(target=_render_share, args=(calls, start, jobs), daemon=True)
                             for start in range(jobs)]
            for child in self.children:
                child.start()

    def wait(self) -> list[Path]:
        """The paths written, once every figure is."""
        if not self.children:
            return [call[0](*call[1:]) for call in self.calls]
        for child in self.children:
            child.join()
        failed = [child.exitcode for child in self.children if child.exitcode != 0]
        if failed:
            raise RuntimeError(f"figure writing failed in {len(failed)} of {len(self.children)} processes "
                               f"(exit codes {failed})")
        return [call[-1] for call in self.calls]


def render(calls: list[tuple], jobs: int = 1) -> list[Path]:
    """Draw figure ``calls`` in ``jobs`` processes (:class:`Rendering`); return their paths."""
    return Rendering(calls, jobs).wait()


def _render_share(calls: list[tuple], start: int, stride: int) -> None:
    import os
    import traceback

    try:
        for call in calls[start::stride]:
            call[0](*call[1:])
    except BaseException:  # noqa: BLE001 - reported through the exit code
        traceback.print_exc()
        os._exit(1)
    os._exit(0)  # no interpreter teardown in a forked child: the parent owns every resource


def nominal_figures(t, with_damper: dict, without_damper: dict, folder: Path, title: str) -> list[Path]:
    """Fig. 3: (a) the main mass with and without the damper, (b) each barrier's voltage."""
    fig, ax = _figure((7.5, 4.2))
    ax.plot(t, 1e3 * without_damper["main_displacement"], color="0.55", lw=1.0, label="without damper")
    ax.plot(t, 1e3 * with_damper["main_displacement"], color="C0", lw=1.0, label="with piezo-impact damper")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("main mass displacement $p$ (mm)")
    ax.set_title(f"Fig. 3(a): main mass with and without the damper ({title})", fontsize=9)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    ax.grid(alpha=0.3)
    a = _save(fig, Path(folder) / "fig3a.png")

    fig, axes = _figure((7.5, 5.2), 2, 1, sharex=True)
    for ax, side, color in zip(axes, ("left", "right"), ("C1", "C2")):
        ax.plot(t, with_damper[f"voltage_{side}"], color=color, lw=0.8)
        ax.set_ylabel(f"$V$ {side} barrier (V)")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(f"Fig. 3(b): output voltage of each piezoelectric barrier ({title})", fontsize=9)
    return [a, _save(fig, Path(folder) / "fig3b.png")]


def two_designs_figure(t, runs: dict, folder: Path, title: str) -> Path:
    """Fig. 10: (a) the main mass and (b) the running RMS voltage of the two designs."""
    fig, axes = _figure((12, 4.4), 1, 2)
    for (label, series), color in zip(runs.items(), ("C0", "C3")):
        axes[0].plot(t, 1e3 * series["main_displacement"], color=color, lw=0.9, label=label)
        axes[1].plot(t, series["voltage_rms"], color=color, lw=1.2, label=label)
    axes[0].set_ylabel("main mass displacement $p$ (mm)")
    axes[0].set_title("(a) vibratory behaviour", fontsize=9)
    axes[1].set_ylabel("$V_{rms}$ over the impacts so far (V)")
    axes[1].set_yscale("symlog", linthresh=1.0)
    axes[1].set_title("(b) energy behaviour (RMS output voltage, eq. 30)", fontsize=9)
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper center", bbox_to_anchor=(1.1, -0.14), ncol=2, frameon=False)
    fig.suptitle(f"Fig. 10: designed vs poor piezo-impact damper ({title})", fontsize=11)
    return _save(fig, Path(folder) / "fig10.png")


def load_sweep_figure(rows: list[dict], summary: dict, folder: Path) -> Path:
    """``load_sweep.png``: energy per impact and average power against the load (log-log),
    each model's measured optimum (solid line, star), the estimate ``1/(omega_c C_p)``
    (dashed) and the paper's 52 kOhm (dotted)."""
    fig, axes = _figure((7.5, 7.0), 2, 1, sharex=True)
    panels = (("energy_per_impact_J", 1e6, "harvested energy per impact (µJ)"),
              ("average_power_W", 1e3, "average harvested power (mW)"))
    estimates = {}
    for (m, entry), color in zip(summary["models"].items(), ("C0", "C3", "C2")):
        r = np.array([row["R_load_ohm"] for row in rows if str(row["voltage_model"]) == m])
        estimates.setdefault(round(entry["R_opt_estimate_ohm"], 3), entry["R_opt_estimate_ohm"])
        for ax, (key, factor, _) in zip(axes, panels):
            y = np.array([row[key] for row in rows if str(row["voltage_model"]) == m]) * factor
            ax.plot(r, y, "o-", ms=3, color=color, lw=1.2, label=f"model {m}: {entry['name']}")
            o = entry["optimum"][key]
            if o["index"] is None:
                continue
            at = o["R_refined_ohm"] or o["R_ohm"]
            value = (o["value_refined"] or o["value"]) * factor
            ax.axvline(at, color=color, lw=1.0, alpha=0.8)
            ax.plot(at, value, "*", color=color, ms=13, mec="white", zorder=5,
                    label=f"model {m} optimum: {ohms(at)}, {value:.3g}")
            nominal = entry["nominal_load"]
            ax.plot(nominal["R_load_ohm"], nominal[key] * factor, "s", color=color, ms=5, mfc="none")
    for ax, (_, _, label) in zip(axes, panels):
        for estimate in estimates.values():
            ax.axvline(estimate, color="k", ls="--", lw=1.0,
                       label=f"$R_{{opt}} \\approx 1/(\\omega_c C_p)$ = {ohms(estimate)}")
        ax.axvline(52e3, color="0.5", ls=":", lw=1.0, label="paper's $R_L$ = 52 kΩ (squares)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="lower center")
    axes[-1].set_xlabel("load resistance $R$ (Ω)")
    axes[0].set_title(f"Load sweep: {summary['duration_s']:g} s from the nominal release per point "
                      f"({len(summary['loads_ohm'])} loads)", fontsize=9)
    return _save(fig, Path(folder) / "load_sweep.png")


def ohms(value: float, unit: str = "Ω") -> str:
    """A resistance to 3 digits with an SI prefix: ``52 kΩ``, ``3.59 MΩ`` (``unit="Ohm"``
    for plain text)."""
    for factor, prefix in ((1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, "")):
        if value >= factor:
            return f"{value / factor:.3g} {prefix}{unit}"
    return f"{value:.3g} {unit}"


def impact_figure(series: dict, side: str, load: float, label: str, path: Path) -> Path:
    """The voltage of one impact against time (ms): (a) the quasi-static model 0, (b) the
    circuit models at ``load`` (``label`` names it, or is empty); the barrier's deflection (µm)
    on a twin axis of each panel.

    ``series`` maps the voltage model to its sampled outputs (``time``, ``voltage_<side>``,
    ``deflection_<side>``)."""
    groups = [g for g in ([m for m in series if m == 0], [m for m in series if m != 0]) if g]
    fig, axes = _figure((7.5, 3.0 * len(groups) + 0.6), len(groups), 1, sharex=True, squeeze=False)
    names = {0: "model 0, quasi-static $k_V\\,\\delta$ (open circuit)", 1: "model 1, circuit one-way",
             2: "model 2, circuit coupled"}
    colors = {0: "C1", 1: "C0", 2: "C3"}
    for ax, group in zip(axes[:, 0], groups):
        twin = ax.twinx()
        for m in group:
            s = series[m]
            t = 1e3 * s["time"]
            ax.plot(t, s[f"voltage_{side}"], color=colors.get(m, "C4"), lw=1.3, label=names.get(m, f"model {m}"))
            twin.plot(t, 1e6 * s[f"deflection_{side}"], color=colors.get(m, "C4") if m else "0.3", lw=0.9,
                      ls=(0, (4, 3)), alpha=0.7)
            ax.plot([], [], color=colors.get(m, "C4") if m else "0.3", lw=0.9, ls=(0, (4, 3)),
                    label=f"deflection δ, model {m} (right axis)")
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_ylabel(f"voltage, {side} barrier (V)")
        twin.set_ylabel("tip deflection δ (µm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
        circuit = group != [0]
        ax.set_title(f"across $R$ = {ohms(load)}{f' ({label} load)' if label else ''}" if circuit
                     else "open-circuit voltage (independent of the load)", fontsize=9)
    axes[-1, 0].set_xlabel("time (ms)")
    fig.suptitle(f"First impact: voltage under the voltage models, $R$ = {ohms(load)}", fontsize=10)
    return _save(fig, Path(path))


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
    frequency ratio, as calls for :class:`Rendering`; bands where the two directions differ are
    shaded, points that did not settle are drawn hollow."""
    panels = (
        ("amplitude", 1e3, "main mass amplitude (mm), half peak-to-peak", ("with", "without"), "amplitude.png"),
        ("harvested_power", 1e3, "harvested power, both loads (mW)", ("with",), "power.png"),
        ("impacts_per_cycle", 1.0, "impacts per forcing cycle", ("with",), "impacts.png"),
    )
    return [(_frequency_figure, ds, *panel[:4], Path(folder) / panel[4]) for panel in panels]


def _frequency_figure(ds, key: str, factor: float, label: str, cases: tuple, path: Path) -> Path:
    from .analysis import bands

    ratio = ds["ratio"].values
    half_step = 0.5 * (ratio[-1] - ratio[0]) / max(1, len(ratio) - 1)
    fig, ax = _figure((7.5, 4.6))
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
            if (~settled).any():
                ax.plot(ratio[~settled], y[~settled], ls="none", marker=style["marker"] or "o", ms=6,
                        mfc="none", color=style["color"])
    if key == "amplitude":
        linear = ds["transmissibility_linear"].values * ds["base_amplitude"].values * factor
        ax.plot(ratio, linear, color="k", ls=":", lw=1.0, label="without damper, closed form")
        ax.set_yscale("log")
    elif key == "harvested_power":
        ax.set_yscale("symlog", linthresh=1e-2)  # zero where nothing impacts, decades where it does
    if differ.any():
        ax.axvspan(np.nan, np.nan, color="C1", alpha=0.15, label="up and down differ (with damper)")
    ax.plot([], [], ls="none", marker="o", mfc="none", color="0.3", label="not settled (hollow)")
    ax.set_xlabel(r"frequency ratio $\omega / \sqrt{K/M}$")
    ax.set_ylabel(label)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(f"Frequency response: {ds.attrs['excitation']}", fontsize=9)
    return _save(fig, path)


def convergence_figure(records: list[dict], report: dict, path: Path) -> Path:
    """``convergence.png``: the objective of every evaluation of the search in order, the best so
    far, and the best point of the grid of the same budget."""
    search = sorted((r for r in records if r.get("phase") == "search"), key=lambda r: r["index"])
    values = np.array([r["objective"] if r["objective"] is not None else np.nan for r in search], float)
    values[~np.isfinite(values)] = np.nan
    fig, ax = _figure((7.5, 4.2))
    ax.plot(np.arange(1, len(values) + 1), values, ".", ms=4, color="C0", alpha=0.6, label="evaluations")
    ax.plot(np.arange(1, len(values) + 1), np.fmin.accumulate(np.where(np.isnan(values), np.inf, values)),
            color="C3", lw=1.5, label="best so far")
    grid = report.get("grid")
    if grid and grid.get("best"):
        ax.axhline(grid["best"]["objective"], color="k", ls="--", lw=1.0,
                   label=f"best of the grid of the same budget ({grid['evaluations']} points)")
    ax.set_xlabel("evaluation (differential evolution, then its polish)")
    ax.set_ylabel("objective J (minimised)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"Optimisation, {report['objective']} objective: {report['search']['evaluations']} evaluations, "
                 f"{report['search']['wall_s']:.1f} s", fontsize=9)
    return _save(fig, path)
