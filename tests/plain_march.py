"""The FMU marched under harmonic base motion with fmpy alone: no harness code, so that what the
steady-state search reports can be checked by an independent route.

The base is what :class:`piezo_fmu_harness.periodic.drive.HarmonicDrive` gives the FMU (its module
text states it), written here again from that statement: ``samples`` communication steps per
forcing period, node values ``y_k = A sin(phase + 2 pi k / samples)`` with ``A = Y / sinc^2(pi /
samples)``, and on each step the slope ``v_k = (y_{k+1} - y_k) / h`` (a first-order hold).

No side effects at import.
"""

from __future__ import annotations

import math
import shutil
import tempfile

import numpy as np
from fmpy import extract, instantiate_fmu, read_model_description

#: The outputs read after every step, in the order of the section state x = (p, p', q, q').
STATE = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity")


def march(fmu_path, values: dict, omega: float, amplitude: float, x, phase: float, periods: int,
          samples: int = 64) -> dict:
    """March the FMU ``periods`` forcing periods from the state ``x = (p, p', q, q')`` at base
    phase ``phase`` (rad), the other parameters ``values`` (SI; integers for Integer ones).

    Returns ``impacts`` (the impact onsets in each period), ``p`` and ``dp`` (after every step,
    the start first) and ``sections`` (the state at the end of each period)."""
    description = read_model_description(str(fmu_path))
    refs = {v.name: (v.valueReference, v.type) for v in description.modelVariables}
    unzipdir = extract(str(fmu_path), unzipdir=tempfile.mkdtemp())
    fmu = instantiate_fmu(unzipdir, description, fmi_type="CoSimulation")
    try:
        h = 2.0 * math.pi / omega / samples
        scaled = amplitude / (math.sin(math.pi / samples) / (math.pi / samples)) ** 2
        y = [scaled * math.sin(phase + 2.0 * math.pi * k / samples) for k in range(samples + 1)]
        nodes = [(y[k], (y[k + 1] - y[k]) / h) for k in range(samples)]
        start = {**values, "p0": x[0], "dp0": x[1], "q0": x[2], "dq0": x[3]}
        for name, value in start.items():
            ref, kind = refs[name]
            if kind == "Integer":
                fmu.setInteger([ref], [int(value)])
            else:
                fmu.setReal([ref], [float(value)])
        base = [refs["base_displacement"][0], refs["base_velocity"][0]]
        fmu.setReal(base, list(nodes[0]))
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        state_refs = [refs[name][0] for name in STATE]
        count_ref = [refs["impact_count"][0]]
        trace = [fmu.getReal(state_refs)]
        impacts, sections, counted = [], [], fmu.getInteger(count_ref)[0]
        step = 0
        for _ in range(periods):
            for value, slope in nodes:
                fmu.setReal(base, [value, slope])
                fmu.doStep(currentCommunicationPoint=step * h, communicationStepSize=(step + 1) * h - step * h)
                step += 1
                trace.append(fmu.getReal(state_refs))
            total = fmu.getInteger(count_ref)[0]
            impacts.append(total - counted)
            counted = total
            sections.append(np.array(trace[-1]))
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzipdir, ignore_errors=True)
    data = np.array(trace)
    return {"impacts": impacts, "p": data[:, 0], "dp": data[:, 1], "sections": sections, "h": h}


def half_swing(p: np.ndarray, dp: np.ndarray, h: float) -> float:
    """Half the peak-to-peak of the main mass over samples ``p`` (with velocities ``dp``), ``h``
    apart: each extreme sample refined by the parabola through it and its neighbours, whose vertex
    is where the velocity, interpolated linearly, vanishes."""
    def extreme(k: int) -> float:
        k = min(max(k, 1), len(p) - 2)
        a, b, c = dp[k - 1], dp[k], dp[k + 1]
        # The velocity crosses zero between k-1 and k+1: its linear interpolant's root.
        lo, hi = (k - 1, k) if a * b <= 0 else (k, k + 1)
        va, vb = dp[lo], dp[hi]
        s = va / (va - vb) if va != vb else 0.0
        # p at the root: the integral of the linear velocity from sample lo.
        return float(p[lo] + h * s * (va + 0.5 * s * (vb - va)))

    top, bottom = extreme(int(np.argmax(p))), extreme(int(np.argmin(p)))
    return 0.5 * (top - bottom)
