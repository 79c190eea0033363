"""The FMU marched under harmonic base motion with fmpy alone: the independent route by which the
tests check where a study says a start goes.

Nothing of the project's harness or core is used: the FMU is instantiated with fmpy's ``FMU2Slave``,
its parameters set by value reference, and the base given as the first-order hold that the FMU's
inputs describe (``N`` nodes a period whose fundamental is ``Y sin(w t)``, the slope of each step
the chord to the next node), written out here again.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

FMU = Path(__file__).resolve().parents[1] / "fmus" / "PiezoImpactDamper.fmu"


class Marcher:
    """One instance of the FMI 2.0 FMU, reset for every march."""

    def __init__(self, fmu: Path = FMU):
        self.description = read_model_description(str(fmu))
        self.unzipdir = extract(str(fmu))
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.fmu = FMU2Slave(guid=self.description.guid, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.description.coSimulation.modelIdentifier, instanceName="march")
        self.fmu.instantiate()
        self.started = False

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self.unzipdir, ignore_errors=True)

    def _set(self, values: dict) -> None:
        for name, value in values.items():
            v = self.variables[name]
            if v.type == "Integer":
                self.fmu.setInteger([v.valueReference], [int(value)])
            else:
                self.fmu.setReal([v.valueReference], [float(value)])

    def march(self, values: dict, omega: float, amplitude: float, start, periods: int, samples: int = 64,
              phase: float = 0.0, trace: bool = False, until=None) -> dict:
        """``periods`` forcing periods from ``start`` (``p, p', q, q'``) at base phase ``phase``
        (rad): the state at the end of each period (``sections``) and the contact onsets in each
        (``onsets``); with ``trace``, also the largest and smallest sampled ``p`` of each (``top``,
        ``bottom``), and ``p`` and ``p'`` after every step, the start first (``p``, ``dp``), ``h`` s
        apart. Without it the FMU is read only at the period's end: what it reads there is the same
        to the bit (``test_fmu``: which outputs a host reads, and when, changes no motion it reads),
        and a long march is about a third faster (a reading goes through fmpy and books the FMU's
        energy ledger: about a third of a step's cost under the moving base). With ``until`` (a
        function of the run so far), the march stops early at the end of the first period, among
        every :data:`LOOK`-th, where it returns True: ``periods`` is then a cap."""
        if self.started:
            self.fmu.reset()
        self.started = True
        n = samples
        h = 2.0 * math.pi / omega / n
        nodes = [amplitude / (math.sin(math.pi / n) / (math.pi / n)) ** 2 * math.sin(phase + 2.0 * math.pi * k / n)
                 for k in range(n + 1)]
        slopes = [(nodes[k + 1] - nodes[k]) / h for k in range(n)]
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self._set({**values, "p0": start[0], "dp0": start[1], "q0": start[2], "dq0": start[3]})
        self._set({"base_displacement": nodes[0], "base_velocity": slopes[0]})
        self.fmu.exitInitializationMode()
        refs = [self.variables[name].valueReference for name in ("main_displacement", "main_velocity",
                                                                   "impactor_displacement", "impactor_velocity")]
        inputs = [self.variables["base_displacement"].valueReference, self.variables["base_velocity"].valueReference]
        count_ref = [self.variables["impact_count"].valueReference]
        sections, onsets, tops, bottoms = [], [], [], []
        steps = [self.fmu.getReal(refs[:2])] if trace else []
        count = self.fmu.getInteger(count_ref)[0]
        step = 0
        for period in range(periods):
            p_values = []
            for k in range(n):
                self.fmu.setReal(inputs, [nodes[k], slopes[k]])
                self.fmu.doStep(currentCommunicationPoint=step * h, communicationStepSize=(step + 1) * h - step * h)
                step += 1
                if trace:
                    steps.append(self.fmu.getReal(refs[:2]))
                    p_values.append(steps[-1][0])
            sections.append(self.fmu.getReal(refs))
            now = self.fmu.getInteger(count_ref)[0]
            onsets.append(now - count)
            count = now
            if trace:
                tops.append(max(p_values))
                bottoms.append(min(p_values))
            if until is not None and (period + 1) % LOOK == 0 and until(_run(sections, onsets, h)):
                break
        run = _run(sections, onsets, h)
        if trace:
            steps = np.array(steps)
            run.update(top=np.array(tops), bottom=np.array(bottoms), p=steps[:, 0], dp=steps[:, 1])
        return run


#: Periods between two looks of :meth:`Marcher.march`'s ``until``.
LOOK = 20


def _run(sections: list, onsets: list, h: float) -> dict:
    return {"sections": np.array(sections), "onsets": np.array(onsets), "h": h, "impacts": [int(i) for i in onsets]}


def nudged(start, relative: float, amplitude: float) -> np.ndarray:
    """``start`` moved by ``relative`` of itself; a start at rest (all zero), which that would not
    move, by ``relative`` of ``amplitude`` (m) in both displacements, the gap between them unchanged."""
    start = np.asarray(start, dtype=float)
    if start.any():
        return start * (1 + relative)
    return start + relative * amplitude * np.array([1.0, 0.0, 1.0, 0.0])


def reaches(run: dict, attractor: dict, omega: float, window: int = 40) -> bool:
    """Whether the march ``run`` ends on ``attractor`` (a study's record): an orbit's contact onsets
    in every period of the last ``window`` and its sections within 1e-3 of its size of the orbit's,
    or, for the motion without impacts, no onset in the window with the impact mass at rest."""
    onsets, sections = run["onsets"][-window:], run["sections"][-window:]
    if attractor["kind"] == "no impacts":
        return bool(onsets.sum() == 0 and sections[-1, 3] == 0.0)
    if attractor["kind"] != "orbit":
        return False
    scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
    points = np.array(attractor["sections"], dtype=float)
    size = float(np.abs(points * scale).max())
    gap = np.abs((sections[-1][None] - points) * scale).max(axis=1).min()
    return bool(sorted(set(onsets.tolist())) == sorted(set(attractor["impacts"])) and gap <= 1e-3 * size)


def settled(run: dict, omega: float, window: int = 40) -> bool:
    """The march's last ``window`` sections repeat to 1e-9 of their size at some order up to 4."""
    scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
    last = run["sections"][-window:] * scale
    size = np.abs(last).max()
    return any(np.abs(last[n:] - last[:-n]).max() <= 1e-9 * size for n in range(1, 5))


def ends_as_labelled(marcher: Marcher, values: dict, omega: float, amplitude: float, start, attractor: dict,
                     periods: int) -> bool:
    """Whether a start that a study labelled after ``periods`` periods ends on ``attractor`` when
    marched with fmpy alone (200 periods more); or else whether its fate hangs on the last bits: the
    same start moved by 1e-12 of itself (:func:`nudged`) parts from it by 1e-3 of the state's size
    within ``periods`` (a chaotic transient, whose end no double-precision code predicts). False
    otherwise."""
    start = np.asarray(start, dtype=float)
    run = marcher.march(values, omega, amplitude, start, periods + 200)
    if attractor["kind"] == "not periodic":
        return not settled(run, omega)
    if reaches(run, attractor, omega):
        return True
    moved = marcher.march(values, omega, amplitude, nudged(start, 1e-12, amplitude), periods)
    scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
    size = np.abs(run["sections"][:periods] * scale).max()
    return bool(np.abs((moved["sections"] - run["sections"][:periods]) * scale).max() > 1e-3 * size)


def march(fmu_path, values: dict, omega: float, amplitude: float, x, phase: float, periods: int,
          samples: int = 64) -> dict:
    """:meth:`Marcher.march` on a fresh instance of the FMU at ``fmu_path``, freed after."""
    marcher = Marcher(fmu_path)
    try:
        return marcher.march(values, omega, amplitude, x, periods, samples, phase, trace=True)
    finally:
        marcher.close()


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
