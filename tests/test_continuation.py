"""Continuation through folds: the branches of the forced response's orbits, their
folds against the sweeps' jumps, and unstable branches against what a disturbed run does."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fmu_host import assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.periodic.drive import HarmonicDrive

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
Y = 1e-3
#: The default damper over 0.7-0.8 w_n at a sweep step of 0.025: sweeping down, the three-impact
#: orbit ends at a fold near 0.753 and the sweep jumps to the two-impact orbits.
BAND = ("--ratio-min", 0.7, "--ratio-max", 0.8, "--count", 5)
STEP = 0.025


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("continuation")
    assert run_cli("continuation", *BAND, "--jobs", 2, "--out", out, "--fmu", FMU) == 0
    return out


def sweeps(folder: Path) -> dict:
    records = [json.loads(line) for line in (folder / "sweeps.jsonl").read_text().splitlines()]
    return {direction: sorted((r for r in records if r["direction"] == direction), key=lambda r: r["lam"])
            for direction in ("up", "down")}


def test_continuation_passes_a_fold_where_a_multiplier_crosses_plus_one(study):
    ds = open_dataset(study / "continuation.nc")
    kinds = ds["event_kind"].values
    folds = np.flatnonzero(kinds == "fold")
    assert len(folds) >= 1
    crossing = folds[ds["event_crosses_plus_one"].values[folds] == 1]
    assert len(crossing) >= 1, "no fold where a real multiplier crosses +1"
    # The branch goes on past the fold: points on both sides of it in arclength, the parameter turning back.
    for k in crossing:
        branch = ds["lam"].values[ds["branch"].values == ds["event_branch"].values[k]]
        assert branch.min() < ds["event_lam"].values[k] < branch.max() or \
            np.sum(branch > ds["event_lam"].values[k]) >= 2


def test_the_sweeps_jump_within_one_frequency_step_of_the_folds_that_end_a_stable_segment(study):
    ds = open_dataset(study / "continuation.nc")
    kinds, plus = ds["event_kind"].values, ds["event_crosses_plus_one"].values == 1
    # A fold that ends a stable part of a branch: a sweep along that part must jump there.
    ending = np.flatnonzero((kinds == "fold") & plus & (ds["event_stability_changes"].values == 1))
    assert ending
    jumps = []
    for records in sweeps(study).values():
        for a, b in zip(records, records[1:]):
            if (a["order"], a["impacts_per_cycle"]) != (b["order"], b["impacts_per_cycle"]) or \
                    abs(a["amplitude"] - b["amplitude"]) > 0.2 * max(a["amplitude"], b["amplitude"]):
                jumps.append((a["lam"], b["lam"]))
    assert jumps
    for k in ending:
        fold = ds["event_lam"].values[k]
        near = [jump for jump in jumps if min(jump) - STEP <= fold <= max(jump) + STEP]
        assert near, (fold, jumps)


def test_points_of_an_unstable_branch_leave_when_disturbed_by_1e_9_Y(study, instance):
    ds = open_dataset(study / "continuation.nc")
    problem = json.loads(ds.attrs["problem"])
    moduli = np.hypot(ds["multiplier_real"].values, ds["multiplier_imag"].values).max(axis=1)
    candidates = np.flatnonzero((ds["stable"].values == 0) & (moduli > 1.2) & (moduli < 20) & (ds["order"].values == 1))
    assert len(candidates) >= 3
    for k in candidates[:: max(1, len(candidates) // 4)][:4]:
        drive = HarmonicDrive(instance, problem["values"], float(ds["omega"].values[k]),
                              float(ds["base_amplitude"].values[k]), problem["samples"])
        state = ds["state"].values[k]
        drive.start(state + np.array([1e-9 * Y, 0.0, 0.0, 0.0]), float(ds["phase"].values[k]))
        periods = math.ceil(math.log(1e5) / math.log(moduli[k])) + 20
        distances = [drive.distance(s, state) for s in drive.advance(periods)]
        assert max(distances) > 1e-4 * Y, (k, moduli[k], distances[-1])
        # ... and on the branch itself it stays: the same start, undisturbed, returns within the tolerance.
        drive.start(state, float(ds["phase"].values[k]))
        assert drive.distance(drive.advance(1)[-1], state) <= 10 * problem["tolerance"] * Y


def test_the_results_carry_branches_stability_and_events(study):
    import pandas

    ds = open_dataset(study / "continuation.nc")
    assert ds.sizes["point"] > 20 and ds.sizes["multiplier"] == 4
    moduli = np.hypot(ds["multiplier_real"].values, ds["multiplier_imag"].values).max(axis=1)
    assert np.array_equal(ds["stable"].values == 1, moduli < 1.0)
    assert ds["amplitude"].attrs["units"] == "m" and ds["omega"].attrs["units"] == "rad/s"
    assert {"branch", "lam", "amplitude_m", "stable"} <= set(pandas.read_csv(study / "branches.csv").columns)
    assert (study / "continuation.png").stat().st_size > 0
    summary = json.loads((study / "summary.json").read_text())
    assert summary["branches"] == len(np.unique(ds["branch"].values)) and summary["evaluations"] > 0


@pytest.mark.parametrize("argv, words", [
    (["--ratio-min", "0"], ["--ratio-min 0", "allowed range (0, inf)"]),
    (["--ratio-min", "0.9", "--ratio-max", "0.8"], ["--ratio-min 0.9", "reversed range"]),
    (["--count", "1"], ["--count 1", "allowed range [2, inf)"]),
    (["--count", "0"], ["--count 0", "allowed range [2, inf)"]),
    (["--set", "m=-1"], ["m = -1.0 is not above 0", "allowed range (0, inf] kg"]),
    (["--parameter", "m", "--range=-1:0.1"], ["--range -1:0.1", "m = -1"]),
    (["--parameter", "m", "--range", "0.2:0.1"], ["--range 0.2:0.1", "reversed range"]),
    (["--parameter", "p0", "--range", "0:1"], ["--parameter p0", "not a parameter that can be continued"]),
    (["--parameter", "Y"], ["--parameter Y needs --range"]),
    (["--max-points", "3"], ["--max-points 3", "allowed range [10, inf)"]),
])
def test_bad_continuation_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "continuation", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "continuation.nc").exists()
