"""Time series of the FMU: one run sampled at a fixed step, its metrics at the end, and CSV."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException

from .fmu import FmuModel, FmuRunError, Instance


#: Communication step of the nominal time series (s).
NOMINAL_STEP = 1e-4


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


def write_csv(path: Path, columns: dict, units: Optional[dict] = None) -> None:
    """A plain CSV with a header row, each column named with its unit (``units``: name -> unit;
    :func:`piezo_fmu_harness.datasets.with_units`); numbers to 12 significant digits, SI units."""
    from .datasets import with_units

    names = [with_units(name, (units or {}).get(name)) for name in columns]
    table = np.column_stack([np.asarray(column, dtype=float) for column in columns.values()])
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.12g")
