"""The nominal case (docs/model.md section 7, the paper's Fig. 3), run through the FMU with fmpy.

Table 1 with ``p(0) = q(0) = 10 mm``, base at rest, ``R_L = 52 kOhm``: the FMU's start values.
Writes into the results folder:

- ``timeseries.csv``: every FMU output at each communication point (1e-4 s by default), and
  the main mass without the damper beside them;
- ``summary.json``: DI (m/s and cm/s), V_rms, P_ave, the impact count, the duration, the
  parameters, and how the case without the damper was made;
- ``fig3a.png``: the main mass with and without the damper; ``fig3b.png``: each barrier's voltage.

Without the damper: the same FMU and the same main mass ``M`` on ``K`` and ``C``, with the gap
``d`` widened to :data:`WIDE_GAP` so that the impact mass never reaches a barrier (the run
checks that it made no impact). The impact mass then exerts no force at all, which is the main
mass alone.

Run it with ``piezo-fmu nominal`` (or ``python -m piezo_fmu_harness nominal``).
"""

from __future__ import annotations

import json
from pathlib import Path

from ..checks import assignments, open_model, preflight, times
from ..drawing import new_figure, save_png
from ..fmu import FmuModel, Instance, discard
from ..series import NOMINAL_STEP, metrics_at_end, simulate_series, write_csv
from ..spec import DEFAULT_STOP_TIME

#: The gap (m) that removes the damper: far beyond any excursion of the impact mass relative
#: to the main mass (twice the 10 mm release amplitude).
WIDE_GAP = 1.0
DEFAULT_OUT = Path("results") / "nominal"


def run_nominal(model: FmuModel, out: Path = DEFAULT_OUT, stop_time: float = DEFAULT_STOP_TIME,
                step: float = NOMINAL_STEP, overrides: dict | None = None,
                instance: Instance | None = None) -> dict:
    """Run the nominal case (with ``overrides`` of its parameters) and write its files.

    Returns the summary written to ``summary.json``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    overrides = dict(overrides or {})
    own = instance is None
    unzipdir = model.extract() if own else instance.unzipdir
    instance = instance or Instance(model, unzipdir)
    try:
        with_damper = simulate_series(model, instance, overrides, stop_time, step)
        without_damper = simulate_series(model, instance, {**overrides, "d": WIDE_GAP}, stop_time, step)
    finally:
        if own:
            instance.free()
            discard(unzipdir)
    if int(without_damper["impact_count"][-1]) != 0:
        raise RuntimeError(f"the run without damper (d = {WIDE_GAP} m) still made impacts; widen WIDE_GAP")

    parameters = {**model.defaults(), **overrides}
    columns = {name: with_damper[name] for name in with_damper.dtype.names}
    columns["main_displacement_without_damper"] = without_damper["main_displacement"]
    columns["main_velocity_without_damper"] = without_damper["main_velocity"]
    files = {"timeseries": out / "timeseries.csv", "summary": out / "summary.json"}
    write_csv(files["timeseries"], columns, {**model.units, "time": "s", "main_displacement_without_damper": "m",
                                             "main_velocity_without_damper": "m/s"})

    changed = ", ".join(f"{k} = {v:g}" for k, v in overrides.items())
    title = f"{'nominal' if not changed else 'nominal with ' + changed}, {stop_time:g} s"
    fig3a, fig3b = nominal_figures(with_damper["time"], with_damper, without_damper, out, title)
    files.update(fig3a=fig3a, fig3b=fig3b)

    summary = {
        "case": "nominal (docs/model.md section 7): Table 1, p(0) = q(0) = 10 mm, base at rest, R_load = 52 kOhm",
        "duration_s": stop_time,
        "communication_step_s": step,
        **metrics_at_end(with_damper),
        "without_damper": {
            "method": (f"the same FMU with the gap d = {WIDE_GAP:g} m: the impact mass never reaches a barrier, "
                       "so the same main mass M moves on K and C alone"),
            "d_m": WIDE_GAP,
            **metrics_at_end(without_damper),
        },
        "parameters": parameters,
        "parameter_units": {name: model.parameters[name].unit or "1" for name in parameters},
        "overrides": overrides,
        "fmu": {"path": str(model.path), "guid": model.guid},
        "files": {key: str(path) for key, path in files.items()},
    }
    files["summary"].write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def summary_lines(summary: dict) -> list[str]:
    """The summary as the few lines ``make nominal`` prints."""
    free = summary["without_damper"]
    return [
        f"nominal case, {summary['duration_s']:g} s simulated (communication step {summary['communication_step_s']:g} s)",
        f"  impacts          {summary['impact_count']}",
        f"  DI (eq. 29)      {summary['DI_cm_per_s']:.4f} cm/s  ({summary['DI_m_per_s']:.6g} m/s); "
        f"without damper {free['DI_cm_per_s']:.4f} cm/s",
        f"  V_rms (eq. 30)   {summary['V_rms_V']:.4g} V",
        f"  P_ave (eq. 30)   {summary['P_ave_W']:.4g} W",
        f"  energy ledger    {summary['energy_balance_error_J']:.2e} J residual",
        f"  files in         {Path(summary['files']['summary']).parent}",
    ]


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


#: The files ``nominal`` writes.
FILES = ("timeseries.csv", "summary.json", "fig3a.png", "fig3b.png")


def command(args) -> int:
    from ..store import claim_folder

    model = open_model(args)
    overrides = assignments(model, args.set)
    stop_time, step = times(args, NOMINAL_STEP)
    unzipdir, instance = preflight(model, [overrides], "--set")
    try:
        out = claim_folder(args.out, FILES, args.force, "nominal run")
        summary = run_nominal(model, out, stop_time, step, overrides, instance=instance)
    finally:
        instance.free()
        discard(unzipdir)
    print("\n".join(summary_lines(summary)))
    return 0


def register(commands) -> None:
    """``piezo-fmu nominal``."""
    from ..options import time_series

    nominal = commands.add_parser("nominal", help="the nominal case (Fig. 3): time series and figures",
                                  description="Run the nominal case (Table 1, released 10 mm from rest) through the "
                                              "FMU, with and without the damper. Writes " + ", ".join(FILES) + ".")
    time_series(nominal, "nominal")
    nominal.set_defaults(run=command)
