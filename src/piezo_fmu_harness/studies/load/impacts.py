"""The voltage of a single impact under each voltage model, through the FMU with fmpy.

**Single impact** (``piezo-fmu impact-voltage``, and after a load sweep). The first impact of
the run, sampled every microsecond (the FMU steps coarsely up to it: its events are exact
whatever the step), under the quasi-static model 0 (open circuit, ``k_V delta``) and the
circuit models at given loads, with the barrier's deflection. Writes ``impact_<load>.png`` and
``impact_<load>.csv`` per load and ``impact.json``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
from fmpy.fmi1 import FMICallException

from ...fmu import FmuModel, FmuRunError, Instance
from ...series import write_csv
from ...spec import DEFAULT_STOP_TIME
from .sweep import MODEL_NAMES, json_text, ohm_text

#: The files the single impacts write (glob patterns: a figure and a table a load).
FILES = ("impact_*.png", "impact_*.csv", "impact.json")
#: Sampling of a single impact (s), and the step that finds it (s).
IMPACT_STEP = 1e-6
LOCATE_STEP = 1e-4
#: Communication step up to the window of a single impact (s); the FMU is exact across it.
APPROACH_STEP = 1e-3
#: Margins of the single-impact window before onset and after the contact, in contact durations.
MARGIN_BEFORE, MARGIN_AFTER = 0.1, 0.5
#: Models shown in a single-impact figure by default.
DEFAULT_IMPACT_MODELS = (0, 1, 2)


def locate_first_impact(instance: Instance, values: dict, stop_time: float) -> dict:
    """The first contact of a run (quasi-static model: the motion before it is the same under
    every model): the time span that holds its onset and end (to :data:`LOCATE_STEP`), and
    the barrier hit."""
    names = ("impact_count", "deflection_left", "deflection_right")
    onset = side = None
    n_steps = max(1, math.ceil(stop_time / LOCATE_STEP - 1e-9))
    t = 0.0
    try:
        instance.start({**values, "voltage_model": 0})
        for k in range(1, n_steps + 1):
            before, t = t, stop_time if k == n_steps else k * LOCATE_STEP
            instance.fmu.doStep(currentCommunicationPoint=before, communicationStepSize=t - before)
            now = instance.read(names)
            if onset is None and now["impact_count"] >= 1:
                onset = before
            if onset is not None:
                if side is None:
                    side = "left" if now["deflection_left"] != 0 else "right" if now["deflection_right"] != 0 else None
                if now["deflection_left"] == 0 and now["deflection_right"] == 0:
                    # A contact shorter than LOCATE_STEP shows no deflection: take the right one.
                    return {"onset_after_s": onset, "end_before_s": t, "side": side or "right"}
    except FMICallException as error:
        raise instance.failure(error) from None
    raise FmuRunError(f"no complete impact within {stop_time:g} s")


def sample_window(instance: Instance, values: dict, start: float, stop: float, step: float,
                  names: tuple) -> dict:
    """Outputs ``names`` every ``step`` from ``start`` to ``stop`` (s) of a run from t = 0 with
    ``values``; the FMU is stepped by :data:`APPROACH_STEP` up to ``start``."""
    count = int(round((stop - start) / step))
    times = start + step * np.arange(count + 1)
    table = {name: np.empty(count + 1) for name in names}
    try:
        instance.start(values)
        t = 0.0
        while t < start:
            size = min(APPROACH_STEP, start - t)
            instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=size)
            t = t + size if start - (t + size) > 1e-15 else start
        for k in range(count + 1):
            if k:
                instance.fmu.doStep(currentCommunicationPoint=times[k - 1],
                                    communicationStepSize=times[k] - times[k - 1])
            for name, value in instance.read(names).items():
                table[name][k] = value
    except FMICallException as error:
        raise instance.failure(error) from None
    return {"time": times, **table}


def run_impacts(model: FmuModel, out: Path, instance: Instance, loads: dict, models=DEFAULT_IMPACT_MODELS,
                step: float = IMPACT_STEP, overrides: Optional[dict] = None,
                stop_time: float = DEFAULT_STOP_TIME) -> dict:
    """The first impact under each model in ``models`` at each load of ``loads``
    (``{label: R}``; a label that is :func:`ohm_text` of its load adds nothing to the
    figure), sampled every ``step``; writes a figure and a CSV per load and
    ``impact.json``. Returns what ``impact.json`` holds."""
    out = Path(out)
    overrides = dict(overrides or {})
    found = locate_first_impact(instance, overrides, stop_time)
    duration = found["end_before_s"] - found["onset_after_s"]
    start = max(0.0, found["onset_after_s"] - MARGIN_BEFORE * duration)
    start = math.floor(start / step) * step
    stop = found["end_before_s"] + MARGIN_AFTER * duration
    side = found["side"]
    names = (f"voltage_{side}", f"deflection_{side}", f"harvested_energy_{side}", "last_impact_voltage",
             "impact_count")
    result = {"duration_s": stop_time, "sampling_step_s": step, "window_s": [start, stop], "barrier": side,
              "overrides": overrides, "loads": {}, "fmu": {"path": str(model.path), "guid": model.guid}}
    from . import figures as curves

    for label, load in loads.items():
        series, entries = {}, {}
        for m in models:
            s = sample_window(instance, {**overrides, "voltage_model": m, "R_load": load}, start, stop, step, names)
            after = s["impact_count"] >= 1
            voltage = s[f"voltage_{side}"]
            peak = int(np.argmax(np.abs(voltage)))
            entries[str(m)] = {
                "name": MODEL_NAMES[m],
                "peak_voltage_sampled_V": float(abs(voltage[peak])),
                "peak_time_s": float(s["time"][peak]),
                "last_impact_voltage_V": float(s["last_impact_voltage"][-1]),
                "energy_harvested_in_window_J": float(s[f"harvested_energy_{side}"][-1]
                                                      - s[f"harvested_energy_{side}"][0]),
                "max_deflection_m": float(np.max(np.abs(s[f"deflection_{side}"]))),
                "impacts_in_window": int(s["impact_count"][-1] - s["impact_count"][0]),
                "onset_s": float(s["time"][np.argmax(after)]) if after.any() else None,
            }
            series[m] = s
        slug = ohm_text(load).replace(" ", "")
        csv = out / f"impact_{slug}.csv"
        columns = {"time": series[models[0]]["time"]}
        units = {"time": "s"}
        for m, s in series.items():
            columns[f"voltage_model{m}"] = s[f"voltage_{side}"]
            columns[f"deflection_model{m}"] = s[f"deflection_{side}"]
            units.update({f"voltage_model{m}": "V", f"deflection_model{m}": "m"})
        write_csv(csv, columns, units)
        figure = curves.impact_figure(series, side, load, "" if label == ohm_text(load) else label,
                                       out / f"impact_{slug}.png")
        result["loads"][label] = {"R_load_ohm": load, "models": entries, "csv": str(csv), "figure": str(figure)}
    (out / "impact.json").write_text(json_text(result))
    return result


def impact_lines(result: dict) -> list[str]:
    """What the single-impact run prints."""
    lines = [f"first impact ({result['barrier']} barrier), {1e3 * result['window_s'][0]:.3f} to "
             f"{1e3 * result['window_s'][1]:.3f} ms, sampled every {result['sampling_step_s']:g} s:"]
    for label, entry in result["loads"].items():
        parts = [f"model {m}: peak {e['peak_voltage_sampled_V']:.4g} V, "
                 f"{e['energy_harvested_in_window_J'] * 1e6:.3g} uJ" for m, e in entry["models"].items()]
        named = "" if label == ohm_text(entry["R_load_ohm"]) else f" ({label})"
        lines.append(f"  {ohm_text(entry['R_load_ohm'])}{named}: " + "; ".join(parts))
        lines.append(f"    {entry['figure']}")
    return lines
