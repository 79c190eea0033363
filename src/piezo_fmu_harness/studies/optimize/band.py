"""The forced objective's sweeps of its band (:mod:`.search`).

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import numpy as np

from ...fmu import FmuRunError, Instance
from ...periodic.band import FrequencySpec, rest_state, solve_point


def sweep_band(instance: Instance, band: FrequencySpec, values: dict, with_damper: bool, direction: str = "up") -> dict:
    """One sweep of the band, up or down, each frequency from the previous one's state: the peak
    amplitude and transmissibility of the stable response, the mean harvested power and how many
    frequencies had no stable orbit."""
    state, phase = rest_state(), 0.0
    amplitudes, transmissibilities, powers, unsettled = [], [], [], 0
    for omega in (band.omegas if direction == "up" else band.omegas[::-1]):
        point = solve_point(instance, 0, values, float(omega), band.base_amplitude(float(omega)), band.settings,
                            state, phase)
        if point["status"] != "ok":
            raise FmuRunError(point["error"])
        state, phase = point["state"], point["phase"]
        amplitudes.append(point["amplitude"])
        transmissibilities.append(point["transmissibility"])
        powers.append(point["harvested_power"])
        unsettled += not point["settled"]
        if not with_damper and point["impacts_per_cycle"] > 0:
            raise FmuRunError(f"the run without the damper (d = {values['d']:g} m) made impacts")
    return {"amplitude": max(amplitudes), "transmissibility": max(transmissibilities),
            "power": float(np.mean(powers)), "unsettled": unsettled}
