"""The frequency response: steady states under harmonic base motion, through the FMU.

The linear limit is checked against the closed form of the base-excited oscillator; the
steady-state detection against a known periodic orbit and a case that cannot settle; the two
sweep directions against each other; resume against an uninterrupted run; bad input against
exit status 2.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from fmu_host import assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.periodic.drive import HarmonicDrive
from piezo_fmu_harness.periodic.band import linear_transmissibility, solve_point
from piezo_fmu_harness.periodic.steady_state import Settings

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
M, K, C = 1.0, 1000.0, 0.1
NATURAL = math.sqrt(K / M)
#: The nominal damper with C_eq = 100 N s/m at Y = 4 mm, w/w_n 0.5 to 0.725: it impacts at every
#: frequency, four times a cycle, on one orbit whichever way the sweep goes.
IMPACT_COUNT = 4
IMPACT_STUDY = ("frequency-response", "--set", "C_eq=100", "--amplitude", 4e-3, "--ratio-min", 0.5, "--ratio-max",
                0.725, "--count", IMPACT_COUNT, "--cycles-per-frequency", 150, "--jobs", 2, "--fmu", FMU, "--no-progress")


@pytest.fixture(scope="module")
def linear_study(tmp_path_factory) -> Path:
    """31 frequencies (w/w_n = 0.5, 0.55, ..., 2), the gap 1 m: no impact anywhere."""
    out = tmp_path_factory.mktemp("linear")
    assert run_cli("frequency-response", "--set", "d=1", "--count", 31, "--tolerance", 1e-9, "--jobs", 2,
                   "--out", out, "--fmu", FMU, "--no-progress") == 0
    return out


@pytest.fixture(scope="module")
def impact_study(tmp_path_factory) -> Path:
    """See :data:`IMPACT_STUDY`."""
    out = tmp_path_factory.mktemp("impacts")
    assert run_cli(*IMPACT_STUDY, "--out", out) == 0
    return out


# -- the linear limit ------------------------------------------------------------------------------

def test_without_impacts_the_response_is_the_closed_form_at_every_frequency(linear_study):
    ds = open_dataset(linear_study / "frequency_response.nc")
    omega = ds["omega"].values
    assert 1.0 in ds["ratio"].values  # the resonance itself is on the grid
    closed = linear_transmissibility(omega, M, K, C)
    assert np.array_equal(ds["transmissibility_linear"].values, closed)
    assert (ds["settled"] == 1).all() and (ds["impacts_per_cycle"] == 0).all()
    for damper in ("with", "without"):
        for direction in ("up", "down"):
            point = ds.sel(damper=damper, direction=direction)
            relative = point["transmissibility"].values / closed - 1.0
            assert np.max(np.abs(relative)) < 1e-6, (damper, direction, relative)
            # A sinusoid's RMS is its amplitude over sqrt(2).
            assert np.allclose(point["rms"].values * math.sqrt(2), point["amplitude"].values, rtol=1e-6, atol=0)
    assert ds["amplitude"].attrs["units"] == "m" and ds["harvested_power"].attrs["units"] == "W"
    assert ds["omega"].attrs["units"] == "rad/s"


def test_a_study_writes_netcdf_csv_summary_and_figures(linear_study):
    import pandas

    table = pandas.read_csv(linear_study / "frequency_response.csv")
    assert len(table) == 4 * 31
    assert {"damper", "direction", "omega_rad_per_s", "ratio", "amplitude_m", "transmissibility", "impacts_per_cycle",
            "V_rms_V", "harvested_power_W", "settled"} <= set(table.columns)
    summary = json.loads((linear_study / "summary.json").read_text())
    peak = summary["resonant_amplitude_m"]["without the damper, sweep up"]
    assert peak["at_ratio"] == 1.0
    assert peak["transmissibility"] == pytest.approx(float(linear_transmissibility(NATURAL, M, K, C)), rel=1e-6)
    for name in ("amplitude.png", "power.png", "impacts.png"):
        assert (linear_study / name).stat().st_size > 0


# -- steady-state detection ------------------------------------------------------------------------

def test_a_known_periodic_orbit_is_detected_as_periodic(instance):
    # The long run's chatter orbit (benchmarks/long_run.py): C = 1, d = 2 mm, C_eq = 10, Y = 5 mm
    # at resonance settles from any start on one period-1 orbit with chatter on both barriers.
    case = {"m": 0.1, "C": 1.0, "d": 2e-3, "C_eq": 10.0}
    settings = Settings()
    orbits = [solve_point(instance, 0, case, NATURAL, 5e-3, settings, start, 0.0)
              for start in ([0.0, 0.0, 0.0, 0.0], [1e-4, 0.0, 1e-4, 0.01])]
    for orbit in orbits:
        assert orbit["status"] == "ok" and orbit["settled"] and orbit["order"] == 1
        assert orbit["return_error"] <= settings.tolerance * 5e-3
        assert orbit["impacts_per_cycle"] >= 4 and orbit["impacts_per_cycle"] == int(orbit["impacts_per_cycle"])
    assert orbits[0]["amplitude"] == pytest.approx(orbits[1]["amplitude"], rel=1e-6)
    assert orbits[0]["impacts_per_cycle"] == orbits[1]["impacts_per_cycle"]


def test_a_case_that_cannot_settle_within_the_cap_is_reported_as_not_settled(instance):
    # Marching alone at resonance from rest: the transient decays by exp(-2 pi zeta) = 0.99 a cycle.
    settings = Settings(newton_iterations=0, max_cycles=30)
    record = solve_point(instance, 0, {"d": 1.0}, NATURAL, 1e-3, settings, [0.0] * 4, 0.0)
    assert record["status"] == "ok"
    assert record["settled"] is False and record["method"] == "none" and record["order"] is None
    assert record["cycles"] <= settings.max_cycles
    # Indeed not periodic: a period from its final state moves it by far more than the tolerance.
    drive = HarmonicDrive(instance, {"d": 1.0}, NATURAL, 1e-3, settings.samples)
    drive.start(record["state"], record["phase"])
    assert drive.distance(drive.advance(1)[-1], record["state"]) > 100 * settings.tolerance * 1e-3
    # With shooting, the same case settles.
    assert solve_point(instance, 0, {"d": 1.0}, NATURAL, 1e-3, Settings(), [0.0] * 4, 0.0)["settled"] is True


def test_every_point_reported_settled_returns_within_the_tolerance_when_run_again(impact_study, instance):
    header = json.loads((impact_study / "frequency_response.json").read_text())
    tolerance = header["settings"]["tolerance"] * header["amplitude_m"]
    records = [json.loads(line) for line in (impact_study / "points.jsonl").read_text().splitlines()]
    settled = [r for r in records if r["settled"]]
    assert len(settled) >= len(records) // 2
    values = header["values"]
    for record in settled:
        gap = values if record["index"] < 2 * IMPACT_COUNT else {**values, "d": header["wide_gap_m"]}
        drive = HarmonicDrive(instance, gap, record["omega"], record["base_amplitude"], header["settings"]["samples"])
        drive.start(record["state"], record["phase"])
        sections = drive.advance(3 * record["order"])
        assert max(drive.distance(s, record["state"]) for s in sections[record["order"] - 1::record["order"]]) \
            <= tolerance, record["index"]


# -- both directions -------------------------------------------------------------------------------

def test_up_and_down_sweeps_agree_away_from_jump_bands(impact_study):
    ds = open_dataset(impact_study / "frequency_response.nc")
    tolerance = 1e-6 * 4e-3
    with_damper = ds.sel(damper="with")
    assert (with_damper["impacts_per_cycle"].values > 0).all()
    assert (ds["settled"] == 1).all()
    both = (with_damper["settled"] == 1).all("direction").values
    differ = with_damper["directions_differ"].values == 1
    up, down = with_damper["amplitude"].sel(direction="up").values, with_damper["amplitude"].sel(direction="down").values
    agree = both & ~differ
    assert agree.sum() >= 3
    assert np.all(np.abs(up - down)[agree] <= tolerance), np.abs(up - down)[agree]
    assert np.all(with_damper["impacts_per_cycle"].sel(direction="up").values[agree]
                  == with_damper["impacts_per_cycle"].sel(direction="down").values[agree])
    # Where they differ, they differ plainly: another orbit, not the same one to the tolerance.
    assert np.all(np.abs(up - down)[both & differ] > 1e3 * tolerance)
    without = ds.sel(damper="without")
    assert np.all(np.abs(without["amplitude"].sel(direction="up") - without["amplitude"].sel(direction="down"))
                  <= tolerance)


# -- backends and resume ---------------------------------------------------------------------------

def test_dask_and_one_process_give_the_same_bits(tmp_path):
    study = ("frequency-response", "--set", "d=1", "--ratio-min", 0.9, "--ratio-max", 1.0, "--count", 2,
             "--fmu", FMU, "--no-progress")
    assert run_cli(*study, "--dask-local", "--jobs", 2, "--out", tmp_path / "dask") == 0
    assert run_cli(*study, "--jobs", 1, "--out", tmp_path / "one") == 0
    dask, one = (open_dataset(tmp_path / name / "frequency_response.nc") for name in ("dask", "one"))
    assert (dask["settled"] == 1).all()
    for key in ("amplitude", "rms", "V_rms", "harvested_power", "impacts_per_cycle", "cycles", "settled"):
        assert np.array_equal(dask[key].values, one[key].values), key


def test_resume_continues_each_chain_from_its_last_finished_point(impact_study, tmp_path):
    shutil.copy(impact_study / "frequency_response.json", tmp_path)
    lines = (impact_study / "points.jsonl").read_text().splitlines(keepends=True)
    by_index = {json.loads(line)["index"]: line for line in lines}
    # Keep the first two points of each chain (up, down, up, down), as an interrupted run leaves them.
    n = IMPACT_COUNT
    kept = [by_index[chain * n + (position if chain % 2 == 0 else n - 1 - position)]
            for chain in range(4) for position in range(2)]
    (tmp_path / "points.jsonl").write_text("".join(kept))
    assert run_cli(*IMPACT_STUDY, "--out", tmp_path, "--resume") == 0
    after = (tmp_path / "points.jsonl").read_text().splitlines(keepends=True)
    assert after[:len(kept)] == kept
    resumed = {json.loads(line)["index"]: json.loads(line) for line in after}
    assert sorted(resumed) == list(range(4 * n))
    for index, line in by_index.items():
        first = json.loads(line)
        for key in ("settled", "amplitude", "impacts_per_cycle", "state", "phase"):
            assert resumed[index][key] == first[key], (index, key)


# -- bad input -------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, words", [
    (["--amplitude", "0"], ["--amplitude 0", "base displacement amplitude", "allowed range (0, inf) m"]),
    (["--amplitude", "nan"], ["--amplitude nan", "allowed range (0, inf) m"]),
    (["--acceleration", "-1"], ["--acceleration -1", "allowed range (0, inf) m/s^2"]),
    (["--ratio-min", "2", "--ratio-max", "1"], ["--ratio-min 2", "--ratio-max 1", "reversed range"]),
    (["--ratio-min", "0"], ["--ratio-min 0", "allowed range (0, inf)"]),
    (["--count", "1"], ["--count 1", "allowed range [2, inf)"]),
    (["--samples", "8"], ["--samples 8", "allowed range [16, inf)"]),
    (["--tolerance", "0.5"], ["--tolerance 0.5", "(0, 0.01]"]),
    (["--cycles-per-frequency", "3"], ["--cycles-per-frequency 3", "allowed range [10, inf)"]),
    (["--newton-iterations", "-1"], ["--newton-iterations -1", "allowed range [0, inf)"]),
    (["--load", "-5"], ["--load -5", "R_load = -5", "allowed range (0, inf) Ohm"]),
    (["--voltage-model", "3"], ["--voltage-model 3", "voltage_model = 3", "above its maximum 2"]),
    (["--set", "p0=0.01"], ["--set p0", "initial state"]),
    (["--set", "R_load=1e6"], ["--set R_load", "--load"]),
    (["--set", "mass=1"], ["unknown parameter 'mass'"]),
    (["--set", "m=-1"], ["m = -1.0 is not above 0"]),
    (["--set", "x1=0.075"], ["the FMU rejects", "x1 + L_p must be <= L"]),
    (["--set", "C=0", "--ratio-min", "0.5", "--ratio-max", "1.5", "--count", "3"],
     ["C = 0.0 N.s/m", "w/w_n = 1 ", "no bounded response", "allowed: C >= 3.16e-11 N.s/m"]),
])
def test_bad_frequency_response_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "frequency-response", argv, words, "--out", out, "--fmu", FMU, "--no-progress")
    assert not (out / "points.jsonl").exists()
