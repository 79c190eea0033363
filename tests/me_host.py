"""Running the FMI 3.0 FMU as Model Exchange in fmpy's CVode, and comparing it with the core:
shared by ``tests/test_model_exchange.py`` and ``benchmarks/bench_me.py``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

ROOT = Path(__file__).resolve().parents[1]
FMU3 = ROOT / "fmus" / "PiezoImpactDamper3.fmu"
STOP_TIME = 2.0


def me_run(rtol: float, stop_time: float = STOP_TIME, **start_values):
    return simulate_fmu(str(FMU3), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol,
                        stop_time=stop_time, output_interval=1e-3, record_events=True, start_values=start_values)


def impact_times(result) -> np.ndarray:
    """The times of the rows at which ``impact_count`` steps up (the row after the update)."""
    return result["time"][np.nonzero(np.diff(result["impact_count"]) > 0)[0] + 1]


def errors(runs: dict, core) -> dict:
    """Per tolerance of ``runs`` (Model Exchange results by rtol) against the core run ``core``:
    the impact count, the time errors (s) of the first impact, of the first ten and of every impact
    both have, the relative errors of V_rms and DI at the end, and the largest ledger error
    relative to the initial energy."""
    reference = np.array([impact.time for impact in core.impacts])
    final = core.readings()
    table = {}
    for rtol, result in runs.items():
        times = impact_times(result)
        n = min(len(times), len(reference))
        table[rtol] = {"count": int(result["impact_count"][-1]), "first": abs(times[0] - reference[0]),
                       "ten": float(np.max(np.abs(times[:10] - reference[:10]))) if n >= 10 else math.inf,
                       "all": float(np.max(np.abs(times[:n] - reference[:n]))),
                       "ledger": float(np.max(np.abs(result["energy_balance_error"]))) / core.energy.initial,
                       "V_rms": abs(result["voltage_rms"][-1] / final["voltage_rms"] - 1.0),
                       "DI": abs(result["damping_inclination"][-1] / final["damping_inclination"] - 1.0)}
    return table
