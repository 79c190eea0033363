"""What a motion on no orbit is: a modulated motion and a chaotic one of the default
damper, measured by the harness's Lyapunov exponent from the period map's Jacobians, and confirmed
independently: by two nearby starts marched side by side, and by the spectrum of the section
samples. One trajectory marched to a cap is reported undecided, the window's class kept
beside it: whether the motion persists is shown by the studies of many starts
(tests/test_bifurcation.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from piezo_fmu_harness.periodic.band import rest_state, solve_point
from piezo_fmu_harness.periodic.drive import HarmonicDrive
from piezo_fmu_harness.periodic.motion import CHAOS
from piezo_fmu_harness.periodic.steady_state import Settings

NATURAL = math.sqrt(1000.0)
Y = 1e-3
NOMINAL = {"voltage_model": 1}


def separation(instance, omega: float, record: dict, periods: int) -> np.ndarray:
    """Distances (m) between two runs from the record's final state, one kicked by 1e-9 Y in p."""
    drive = HarmonicDrive(instance, NOMINAL, omega, Y, Settings().samples)
    runs = []
    for kick in (0.0, 1e-9 * Y):
        drive.start(np.asarray(record["state"]) + np.array([kick, 0.0, 0.0, 0.0]), record["phase"])
        runs.append(np.array(drive.advance(periods)))
    return np.max(np.abs((runs[0] - runs[1]) * drive.scale), axis=1)


def spectrum_peak(instance, omega: float, record: dict, periods: int = 256) -> float:
    """The largest line of the spectrum of the section samples of p over its median: discrete
    lines stand far above the floor for a quasi-periodic motion, not for a chaotic one."""
    drive = HarmonicDrive(instance, NOMINAL, omega, Y, Settings().samples)
    drive.start(record["state"], record["phase"])
    p = np.array(drive.advance(periods))[:, 0]
    power = np.abs(np.fft.rfft((p - p.mean()) * np.hanning(len(p))))
    return float(power.max() / np.median(power))


@pytest.fixture(scope="module")
def modulated(instance) -> tuple[float, dict]:
    """Sweeping up from the two-impact orbit at 1.1 w_n, past its Neimark-Sacker loss of stability
    (1.2765 w_n): at 1.325 w_n the motion is not periodic."""
    state, phase, record = rest_state(), 0.0, None
    for ratio in (1.1, 1.2, 1.275, 1.3, 1.325):
        record = solve_point(instance, 0, NOMINAL, ratio * NATURAL, Y, Settings(), state, phase)
        state, phase = record["state"], record["phase"]
    return 1.325 * NATURAL, record


@pytest.fixture(scope="module")
def chaotic(instance) -> tuple[float, dict]:
    return NATURAL, solve_point(instance, 0, NOMINAL, NATURAL, Y, Settings(), rest_state(), 0.0)


def test_the_modulated_motion_past_the_neimark_sacker_point_stays_close_to_a_neighbour_with_a_line_spectrum(instance, modulated):
    omega, record = modulated
    assert record["settled"] is False and record["verdict"] == "undecided" and record["motion"] == "undecided"
    assert abs(record["lyapunov_exponent"]) < CHAOS and record["lyapunov_periods"] >= 30
    assert record["modulation"] > 0.5 and record["window_class"] == "strongly modulated"
    # Independently: two starts 1e-9 Y apart stay together (no exponential growth over 150 periods)...
    assert separation(instance, omega, record, 150).max() < 1e-8
    # ... and the section samples' spectrum has discrete lines.
    assert spectrum_peak(instance, omega, record) > 200


def test_the_motion_at_resonance_separates_from_a_neighbour_yet_one_trajectory_leaves_it_undecided(instance, chaotic):
    omega, record = chaotic
    assert record["settled"] is False and record["motion"] == "undecided" and record["window_class"] == "chaotic"
    assert record["lyapunov_exponent"] > 10 * CHAOS
    # Independently: two starts 1e-9 Y apart part to the motion's own size within 60 periods, at an
    # early rate that agrees with the exponent's sign and size ...
    distances = separation(instance, omega, record, 60)
    assert distances.max() > 1e-4
    early = distances[: int(np.argmax(distances > 1e-6))]
    rate = math.log(early[-1] / 1e-12) / len(early)
    assert rate > 10 * CHAOS
    # ... and the spectrum of its section samples is broadband.
    assert spectrum_peak(instance, omega, record) < 100
