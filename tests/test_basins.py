"""Basins of attraction (issue 23): at 1.2 w_n the default damper has two stable motions (a
two-impact orbit and the orbit without impacts); every start ends on one of them, as continuation
and the closed form know them, and the shares add to 1. Each start's motion is the one the FMU
marched with fmpy alone from it reaches (issue 26): on the coarse grid every start ends on the
two-impact orbit (four of them used to be reported without impacts, Newton's landing on that
family from motions that still impacted); the motion without impacts takes the starts near its
own state."""

from __future__ import annotations

import json
import math
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from fmu_host import assert_refused, run_cli
from plain_march import half_swing, march

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.periodic.band import linear_transmissibility

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
RATIO, Y = 1.2, 1e-3
GRID = ("--ratio", RATIO, "--p0=-0.005:0.005:4", "--dp0=-0.2:0.2:4", "--fmu", FMU, "--no-progress")
#: Starts at and beside the motion without impacts: p0 = 0 and p0' about its own -0.086 m/s at
#: phase 0 (the impact mass in the middle stays clear of the barriers), and p0 = 2 mm.
NEAR = ("--ratio", RATIO, "--p0=0:0.002:2", "--dp0=-0.1:-0.05:2", "--fmu", FMU, "--no-progress")
#: Periods the FMU is marched alone from each start: the slowest transient on these grids ends
#: its irregular impacts within 200, and the two-impact orbit's multiplier (0.97) then brings the
#: amplitude within 1e-3 in 230 more. Without impacts only the main mass's own damping brings it
#: there (0.8% a period): three times as long.
PLAIN_PERIODS = 500
#: Same attractor: the basin map's own test (amplitudes within 1e-3 relative).
SAME = 1e-3


@pytest.fixture(scope="module")
def basins(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("basins")
    assert run_cli("basins", *GRID, "--jobs", 2, "--out", out) == 0
    return out


@pytest.fixture(scope="module")
def branches(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("branches")
    assert run_cli("continuation", "--ratio-min", 1.1, "--ratio-max", 1.25, "--count", 4, "--jobs", 2, "--out", out,
                   "--fmu", FMU) == 0
    return out


def test_the_shares_add_to_one_and_every_start_of_the_coarse_grid_ends_on_the_two_impact_orbit(basins):
    summary = json.loads((basins / "summary.json").read_text())
    assert summary["starts"] == 16
    assert sum(a["share"] for a in summary["attractors"]) == pytest.approx(1.0, abs=1e-12)
    assert sum(a["starts"] for a in summary["attractors"]) == 16
    kinds = {(a["kind"], a.get("impacts_per_cycle")) for a in summary["attractors"]}
    assert kinds == {("stable orbit", 2.0)}  # what marching alone finds too (below)
    ds = open_dataset(basins / "basins.nc")
    assert set(np.unique(ds["attractor"].values)) == set(range(ds.sizes["attractor"]))
    assert (basins / "basins.png").stat().st_size > 0


def test_every_start_ends_on_a_stable_orbit_that_continuation_or_the_closed_form_knows(basins, branches):
    records = [json.loads(line) for line in (basins / "points.jsonl").read_text().splitlines()]
    branch = open_dataset(branches / "continuation.nc")
    stable = branch["stable"].values == 1
    M, K, C = 1.0, 1000.0, 0.1
    linear = Y * float(linear_transmissibility(RATIO * math.sqrt(K / M), M, K, C))
    for record in records:
        assert record["settled"] and record["max_multiplier"] < 1.0, record["index"]
        if record["impacts_per_cycle"] == 0:
            assert record["amplitude"] == pytest.approx(linear, rel=1e-6)
            continue
        # On a stable part of a branch, at this frequency: the amplitude interpolated between the
        # two branch points around 1.2 w_n.
        near = [k for k in np.flatnonzero(stable) if abs(branch["lam"].values[k] - RATIO) < 0.02
                and branch["impacts_per_cycle"].values[k] == record["impacts_per_cycle"]
                and branch["order"].values[k] == record["order"]]
        assert near, record["index"]
        lam, amplitude = branch["lam"].values[near], branch["amplitude"].values[near]
        order = np.argsort(lam)
        assert record["amplitude"] == pytest.approx(float(np.interp(RATIO, lam[order], amplitude[order])), rel=2e-3)


def plain_end(header: dict, record: dict) -> tuple[list, float]:
    """The FMU marched with fmpy alone from a start: the impacts of its last 50 periods and its
    half peak-to-peak over the last two."""
    periods = PLAIN_PERIODS if record["impacts_per_cycle"] else 3 * PLAIN_PERIODS
    plain = march(FMU, header["values"], header["omega"], header["amplitude"],
                  [record["p0"], record["dp0"], record["p0"], 0.0], 0.0, periods)
    last = slice(-2 * header["settings"]["samples"] - 1, None)
    return plain["impacts"][-50:], half_swing(plain["p"][last], plain["dp"][last], plain["h"])


def plain_ends(folder: Path) -> list[tuple[dict, list, float]]:
    """Each start of a map with :func:`plain_end`, on two processes."""
    header = json.loads((folder / "basins.json").read_text())
    records = [json.loads(line) for line in (folder / "points.jsonl").read_text().splitlines()]
    with ProcessPoolExecutor(2) as pool:
        ends = list(pool.map(plain_end, [header] * len(records), records))
    return [(record, impacts, amplitude) for record, (impacts, amplitude) in zip(records, ends)]


def test_every_start_ends_where_the_fmu_marched_alone_goes(basins):
    for record, impacts, amplitude in plain_ends(basins):
        assert impacts == [record["impacts_per_cycle"]] * 50, record["index"]
        assert amplitude == pytest.approx(record["amplitude"], rel=SAME), record["index"]


def test_the_motion_without_impacts_takes_the_starts_near_its_own_state(tmp_path):
    assert run_cli("basins", *NEAR, "--jobs", 1, "--out", tmp_path) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    kinds = {(a["kind"], a.get("impacts_per_cycle")) for a in summary["attractors"]}
    assert kinds == {("stable orbit", 2.0), ("stable orbit", 0.0)}
    for record, impacts, amplitude in plain_ends(tmp_path):
        assert record["settled"] and impacts == [record["impacts_per_cycle"]] * 50, record["index"]
        assert amplitude == pytest.approx(record["amplitude"], rel=SAME), record["index"]


def test_an_interrupted_map_resumes_to_the_same_attractors(basins, tmp_path):
    lines = (basins / "points.jsonl").read_text().splitlines(keepends=True)
    (tmp_path / "points.jsonl").write_text("".join(lines[:5]))
    (tmp_path / "basins.json").write_text((basins / "basins.json").read_text())
    assert run_cli("basins", *GRID, "--jobs", 1, "--out", tmp_path, "--resume") == 0
    again = json.loads((tmp_path / "summary.json").read_text())
    first = json.loads((basins / "summary.json").read_text())
    assert [(a["name"], a["starts"]) for a in again["attractors"]] == [(a["name"], a["starts"]) for a in first["attractors"]]


@pytest.mark.parametrize("argv, words", [
    (["--ratio", "0"], ["--ratio 0", "allowed range (0, inf)"]),
    (["--ratio", "-1"], ["--ratio -1", "allowed range (0, inf)"]),
    (["--ratio", "1.2", "--p0=0:0.01:0"], ["--p0 0:0.01:0", "empty grid", "allowed range [1, inf)"]),
    (["--ratio", "1.2", "--dp0=0.1:-0.1:3"], ["--dp0 0.1:-0.1:3", "reversed range"]),
    (["--ratio", "1.2", "--set", "m=-1"], ["m = -1.0 is not above 0", "allowed range (0, inf] kg"]),
    (["--ratio", "1.2", "--amplitude", "0"], ["--amplitude 0", "allowed range (0, inf) m"]),
])
def test_bad_basin_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "basins", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "points.jsonl").exists()
