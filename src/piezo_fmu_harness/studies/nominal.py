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
import shutil
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException

from piezo_fmu_harness.fmu import FmuModel, FmuRunError, Instance
from piezo_fmu_harness.spec import DEFAULT_STOP_TIME

#: Communication step of the nominal time series (s).
NOMINAL_STEP = 1e-4
#: The gap (m) that removes the damper: far beyond any excursion of the impact mass relative
#: to the main mass (twice the 10 mm release amplitude).
WIDE_GAP = 1.0
DEFAULT_OUT = Path("results") / "nominal"


def simulate_series(model: FmuModel, instance: Instance, values: dict, stop_time: float, step: float) -> np.ndarray:
    """Every output of one run at each communication point (fmpy's structured array, SI).

    ``instance`` is reused: it is reset first unless fresh.
    """
    instance.renew()
    try:
        return simulate_fmu(instance.unzipdir, model_description=model.model_description,
                            fmu_instance=instance.fmu, start_values=dict(values), stop_time=stop_time,
                            output_interval=step, output=list(model.outputs), validate=False)
    except FMICallException as error:
        raise FmuRunError("; ".join(dict.fromkeys(instance.messages)) or str(error)) from None


def metrics_at_end(series: np.ndarray) -> dict:
    """The paper's metrics from the last row of a time series (SI, and DI also in cm/s)."""
    last = series[-1]
    di = float(last["damping_inclination"])
    return {
        "impact_count": int(last["impact_count"]),
        "DI_m_per_s": di,
        "DI_cm_per_s": 100.0 * di,
        "V_rms_V": float(last["voltage_rms"]),
        "P_ave_W": float(last["average_power"]),
        "last_impact_voltage_V": float(last["last_impact_voltage"]),
        "energy_dissipated_J": float(last["energy_dissipated"]),
        "energy_balance_error_J": float(last["energy_balance_error"]),
    }


def write_csv(path: Path, columns: dict) -> None:
    """A plain CSV with a header row; numbers to 12 significant digits, SI units."""
    names = list(columns)
    table = np.column_stack([np.asarray(columns[name], dtype=float) for name in names])
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.12g")


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
            shutil.rmtree(unzipdir, ignore_errors=True)
    if int(without_damper["impact_count"][-1]) != 0:
        raise RuntimeError(f"the run without damper (d = {WIDE_GAP} m) still made impacts; widen WIDE_GAP")

    parameters = {**model.defaults(), **overrides}
    columns = {name: with_damper[name] for name in with_damper.dtype.names}
    columns["main_displacement_without_damper"] = without_damper["main_displacement"]
    columns["main_velocity_without_damper"] = without_damper["main_velocity"]
    files = {"timeseries": out / "timeseries.csv", "summary": out / "summary.json"}
    write_csv(files["timeseries"], columns)

    from piezo_fmu_harness import curves

    changed = ", ".join(f"{k} = {v:g}" for k, v in overrides.items())
    title = f"{'nominal' if not changed else 'nominal with ' + changed}, {stop_time:g} s"
    fig3a, fig3b = curves.nominal_figures(with_damper["time"], with_damper, without_damper, out, title)
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
