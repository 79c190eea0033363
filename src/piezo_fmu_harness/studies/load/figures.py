"""The load study's figures: the load sweep and one impact's voltage, in the paper's units."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...drawing import new_figure, ohms, save_png


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
