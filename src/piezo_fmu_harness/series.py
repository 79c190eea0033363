"""Time series of the FMU: one run sampled at a fixed step, its metrics at the end, and CSV."""

from __future__ import annotations

from pathlib import Path

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


def write_csv(path: Path, columns: dict) -> None:
    """A plain CSV with a header row; numbers to 12 significant digits, SI units."""
    names = list(columns)
    table = np.column_stack([np.asarray(columns[name], dtype=float) for name in names])
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.12g")
