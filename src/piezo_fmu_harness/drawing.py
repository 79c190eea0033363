"""Line figures in the paper's units: Fig. 3 (nominal case), Fig. 10 (two designs), the load
sweep, one impact's voltage, the frequency response and the optimiser's convergence.

Like :mod:`piezo_fmu_harness.figures` (the contours of Figs. 4-9), they are made without pyplot
(``matplotlib.figure.Figure``, written by the Agg canvas), so nothing is registered or left to
close. Every function writes PNG files and returns their paths.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import DPI


def new_figure(figsize: tuple, *grid, **kwargs):
    """A new figure and its axes (``Figure.subplots(*grid, **kwargs)``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, **kwargs)


def save_png(fig, path: Path, layout: bool = True) -> Path:
    """Lay out ``fig`` (unless its layout is fixed already), write it to ``path`` (PNG); return
    ``path``."""
    if layout:
        fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


def nominal_figures(t, with_damper: dict, without_damper: dict, folder: Path, title: str) -> list[Path]:
    """Fig. 3: (a) the main mass with and without the damper, (b) each barrier's voltage."""
    fig, ax = new_figure((7.5, 4.2))
    ax.plot(t, 1e3 * without_damper["main_displacement"], color="0.55", lw=1.0, label="without damper")
    ax.plot(t, 1e3 * with_damper["main_displacement"], color="C0", lw=1.0, label="with piezo-impact damper")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("main mass displacement $p$ (mm)")
    ax.set_title(f"Fig. 3(a): main mass with and without the damper ({title})", fontsize=9)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    ax.grid(alpha=0.3)
    a = save_png(fig, Path(folder) / "fig3a.png")

    fig, axes = new_figure((7.5, 5.2), 2, 1, sharex=True)
    for ax, side, color in zip(axes, ("left", "right"), ("C1", "C2")):
        ax.plot(t, with_damper[f"voltage_{side}"], color=color, lw=0.8)
        ax.set_ylabel(f"$V$ {side} barrier (V)")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(f"Fig. 3(b): output voltage of each piezoelectric barrier ({title})", fontsize=9)
    return [a, save_png(fig, Path(folder) / "fig3b.png")]


def two_designs_figure(t, runs: dict, folder: Path, title: str) -> Path:
    """Fig. 10: (a) the main mass and (b) the running RMS voltage of the two designs."""
    fig, axes = new_figure((12, 4.4), 1, 2)
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
    return save_png(fig, Path(folder) / "fig10.png")


def load_sweep_figure(rows: list[dict], summary: dict, folder: Path) -> Path:
    """``load_sweep.png``: energy per impact and average power against the load (log-log),
    each model's measured optimum (solid line, star), the estimate ``1/(omega_c C_p)``
    (dashed) and the paper's 52 kOhm (dotted)."""
    fig, axes = new_figure((7.5, 7.0), 2, 1, sharex=True)
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
    return save_png(fig, Path(folder) / "load_sweep.png")


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
    fig, axes = new_figure((7.5, 3.0 * len(groups) + 0.6), len(groups), 1, sharex=True, squeeze=False)
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
    return save_png(fig, Path(path))


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
    frequency ratio, as calls for :class:`piezo_fmu_harness.figures.Rendering`; bands where the two directions differ are
    shaded, the stable orbits are joined by lines, motions that are not periodic are drawn hollow
    (with their amplitude envelope), and the unstable orbits met are grey crosses."""
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
            loose = ds["verdict"].sel(damper=damper, direction=direction).values == "not periodic"
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
    ax.plot([], [], ls="none", marker="o", mfc="none", color="0.3", label="not periodic (hollow; bar: envelope)")
    if ds.sizes.get("unstable", 0):
        ax.plot([], [], ls="none", marker="x", ms=4, color="0.55", mew=0.8, label="unstable orbit met (never the response)")
    ax.set_xlabel(r"frequency ratio $\omega / \sqrt{K/M}$")
    ax.set_ylabel(label)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(f"Frequency response: {ds.attrs['excitation']}", fontsize=9)
    return save_png(fig, path)


def convergence_figure(records: list[dict], report: dict, path: Path) -> Path:
    """``convergence.png``: the objective of every evaluation of the search in order, the best so
    far, and the best point of the grid of the same budget."""
    search = sorted((r for r in records if r.get("phase") == "search"), key=lambda r: r["index"])
    values = np.array([r["objective"] if r["objective"] is not None else np.nan for r in search], float)
    values[~np.isfinite(values)] = np.nan
    fig, ax = new_figure((7.5, 4.2))
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
    return save_png(fig, path)
