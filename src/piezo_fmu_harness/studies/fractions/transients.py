"""The transients of a fractions study: at each frequency, how long the starts took to
reach their orbits, the share the budget left undecided, the mean transient lifetime with its 95%
interval and the plateau (:func:`piezo_fmu_harness.starts.transients.escape`), and the survival
curve; ``transients.png`` draws the lifetime over frequency and the survival curves of a few
frequencies."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...drawing import FREQUENCY, RATIO, new_figure, save_png
from ...starts.attractors import wilson
from ...starts.transients import escape, survival

#: Points of the survival curve kept over the budget.
CURVE_POINTS = 301
#: Survival curves drawn: the frequencies with the longest lifetimes.
CURVES_DRAWN = 5


def _fits(spec, starts: dict) -> list[dict]:
    rows = []
    for f in range(len(spec.ratios)):
        members = [r for r in starts.values() if r["group"] == f and r["label"] != -2]
        periods = np.array([min(r["periods"], spec.max_cycles) for r in members], float)
        resolved = np.array([r["label"] >= 0 for r in members], bool)
        undecided = sum(1 for r in members if str(r.get("motion", "")).startswith("undecided"))
        rows.append({"periods": periods, "resolved": resolved, "undecided": undecided, "starts": len(members),
                     "fit": escape(periods, resolved, spec.max_cycles) if len(members) else None})
    return rows


def transient_variables(spec, starts: dict, ds):
    """``ds`` with the transients' variables over frequency (see the module's text)."""
    fits = _fits(spec, starts)
    F = len(spec.ratios)
    times = np.unique(np.linspace(0, spec.max_cycles, CURVE_POINTS).round().astype(int))
    curves = np.full((F, len(times)), np.nan)
    numbers = {name: np.full(F, np.nan) for name in (
        "undecided", "undecided_low", "undecided_high", "lifetime", "lifetime_low", "lifetime_high", "plateau",
        "plateau_low", "plateau_high", "median_periods", "last_resolved")}
    persists = np.zeros(F, dtype=np.int8)
    for f, row in enumerate(fits):
        if not row["starts"]:
            continue
        curves[f] = survival(row["periods"], row["resolved"], spec.max_cycles, times)[1]
        numbers["undecided"][f] = row["undecided"] / row["starts"]
        numbers["undecided_low"][f], numbers["undecided_high"][f] = wilson(row["undecided"], row["starts"])
        fit = row["fit"]
        for name in ("lifetime", "lifetime_low", "lifetime_high", "plateau", "plateau_low", "plateau_high"):
            value = getattr(fit, name)
            numbers[name][f] = np.nan if value is None else value
        persists[f] = fit.persists
        done = row["periods"][row["resolved"]]
        numbers["median_periods"][f] = np.median(done) if len(done) else np.nan
        numbers["last_resolved"][f] = done.max() if len(done) else np.nan
    units = {"undecided": ("1", "share of the starts the budget left undecided"),
             "undecided_low": ("1", "95% Wilson interval, low"), "undecided_high": ("1", "95% Wilson interval, high"),
             "lifetime": ("periods", "mean transient lifetime, 1 / escape rate (forcing periods)"),
             "lifetime_low": ("periods", "95% profile-likelihood interval, low"),
             "lifetime_high": ("periods", "95% profile-likelihood interval, high"),
             "plateau": ("1", "share of the starts at risk after the onset that persist (the survival curve's "
                              "plateau)"),
             "plateau_low": ("1", "95% profile-likelihood interval, low"),
             "plateau_high": ("1", "95% profile-likelihood interval, high"),
             "median_periods": ("periods", "median periods the resolved starts took to reach their motion"),
             "last_resolved": ("periods", "the period at which the last resolved start was resolved")}
    for name, (unit, text) in units.items():
        ds[name] = (("omega",), numbers[name], {"units": unit, "long_name": text})
    ds["persists"] = (("omega",), persists, {"units": "1", "long_name": "1 where the survival curve shows a "
                                                                       "plateau: what is left persists"})
    ds = ds.assign_coords(t=("t", times, {"units": "periods", "long_name": "forcing periods marched"}))
    ds["survival"] = (("omega", "t"), curves, {"units": "1", "long_name": "share of the starts unresolved after t "
                                                                         "periods"})
    ds.attrs["budget_periods"] = spec.max_cycles
    ds.attrs["transient_onset_periods"] = fits[0]["fit"].onset if fits and fits[0]["fit"] else 0
    return ds


def by_frequency(ds):
    """A frame of the transients, a row a frequency (``transients.csv``)."""
    import pandas as pd

    names = ("undecided", "undecided_low", "undecided_high", "lifetime", "lifetime_low", "lifetime_high", "plateau",
             "plateau_low", "plateau_high", "persists", "median_periods", "last_resolved")
    frame = pd.DataFrame({"ratio": ds["ratio"].values, "omega": ds["omega"].values,
                          **{name: ds[name].values for name in names}})
    starts = int(ds.attrs["starts_per_frequency"])
    frame.insert(5, "undecided_starts", [int(round(u * starts)) if math.isfinite(u) else 0
                                         for u in frame["undecided"]])
    frame["persists"] = frame["persists"].astype(bool)
    return frame.astype(object).where(frame.notna(), None)


def draw_transients(ds, path: Path) -> Path:
    """``transients.png``: the mean transient lifetime over frequency (log scale, 95% interval) and
    the survival curves of the frequencies with the longest ones."""
    fig, (top, bottom) = new_figure((7.5, 7.0), 2, 1)
    ratio, life = ds["ratio"].values, ds["lifetime"].values
    low, high = ds["lifetime_low"].values, ds["lifetime_high"].values
    shown = np.isfinite(life)
    if shown.any():
        lo = np.where(np.isfinite(low), life - low, 0.0)
        hi = np.where(np.isfinite(high), high - life, 0.0)
        top.errorbar(ratio[shown], life[shown], yerr=[lo[shown], hi[shown]], fmt="o", ms=3, capsize=2, color="C0",
                     label="mean transient lifetime (95% interval)")
        top.set_yscale("log")
    budget = ds.attrs["budget_periods"]
    top.axhline(budget, color="0.5", ls="--", lw=1, label=f"budget ({budget} periods)")
    undecided = ds["undecided"].values
    if np.nansum(undecided) > 0:
        share = top.twinx()
        share.plot(ratio, 100 * undecided, "s-", ms=3, color="C3", label="undecided (%)")
        share.set_ylabel("undecided at the budget (%)", color="C3")
        share.set_ylim(0, 100)
    top.set_xlim(ratio.min() - 0.01, ratio.max() + 0.01)
    top.set_xlabel(FREQUENCY)
    top.set_ylabel("periods")
    top.set_title("How long the starts take to settle", fontsize=9)
    top.legend(fontsize=7, loc="upper left")
    order = [f for f in np.argsort(-np.nan_to_num(life, nan=-1.0)) if np.isfinite(life[f])][:CURVES_DRAWN]
    t = ds["t"].values
    for f in sorted(order):
        curve = ds["survival"].values[f]
        bottom.semilogy(t, np.where(curve > 0, curve, np.nan), label=f"{RATIO} = {ratio[f]:.4g} (lifetime {life[f]:.0f})")
    bottom.set_xlabel("forcing periods marched")
    bottom.set_ylabel("share still unresolved")
    if order:
        bottom.legend(fontsize=7)
    return save_png(fig, path)
