"""Basins of attraction: at 1.2 w_n the default damper has two stable motions,
the two-impact orbit and the motion without impacts. Every start is marched on the batch engine to
the motion its own trajectory reaches; the map is checked here by the independent route, the FMU
marched with fmpy alone: the start that Newton used to send to the motion without impacts
ends on the two-impact orbit, and a random sample of starts ends where the map says."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmpy_march import Marcher, ends_as_labelled, reaches
from fmu_host import DEFECTIVE_C_EQ, assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.periodic.band import linear_transmissibility

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
RATIO, Y = 1.2, 1e-3
W = RATIO * math.sqrt(1000.0)
#: 15 x 15 starts over the default ranges, on which start 4 (p0 = -4.545 mm, p0' = -0.0739 m/s) is
#: the one Newton used to send to the motion without impacts.
GRID = ("--ratio", RATIO, "--grid", 15, "--fmu", FMU, "--no-progress")
ISSUE_START = 4


@pytest.fixture(scope="module")
def basins(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("basins")
    assert run_cli("basins", *GRID, "--jobs", 2, "--out", out) == 0
    return out


@pytest.fixture(scope="module")
def summary(basins) -> dict:
    return json.loads((basins / "summary.json").read_text())


def test_the_summary_gives_the_marching_time_apart_from_the_fmus_checks(summary):
    assert 0 < summary["marching_s"] < summary["wall_s"] and 0 < summary["checking_s"] < summary["wall_s"]
    assert summary["marching_s"] + summary["checking_s"] <= summary["wall_s"]
    assert summary["fmu_checks"]["seconds"] == summary["checking_s"] and summary["fmu_checks"]["checked"] > 0


@pytest.fixture(scope="module")
def marcher():
    m = Marcher(FMU)
    yield m
    m.close()


def values_of(basins: Path) -> dict:
    return json.loads((basins / "basins.json").read_text())["values"]


def label_of(basins: Path, summary: dict, index: int) -> dict:
    ds = open_dataset(basins / "basins.nc")
    label = int(ds["basin"].values.ravel()[index])
    return next(a for a in summary["attractors"] if a["id"] == label)


def test_issue_26s_start_ends_on_the_two_impact_orbit_as_the_fmu_marched_alone_shows(basins, summary, marcher):
    ds = open_dataset(basins / "basins.nc")
    p0, dp0 = ds["p0"].values[0], ds["dp0"].values[ISSUE_START]
    assert (p0, dp0) == (pytest.approx(-4.545e-3, abs=1e-6), pytest.approx(-0.0739, abs=1e-4))
    attractor = label_of(basins, summary, ISSUE_START)
    assert (attractor["kind"], attractor["order"], attractor["impacts"]) == ("orbit", 1, [2])
    assert attractor["amplitude"] == pytest.approx(1.00e-3, rel=5e-3)
    run = marcher.march(values_of(basins), W, Y, (p0, dp0, p0, 0.0), 500, trace=True)
    assert (run["onsets"][-100:] == 2).all()  # it impacts twice in every period
    assert reaches(run, attractor, W)
    assert 0.5 * (run["top"][-1] - run["bottom"][-1]) == pytest.approx(attractor["amplitude"], rel=5e-3)


def test_shares_add_to_one_and_the_two_impact_orbit_takes_more_than_nine_starts_in_ten(basins, summary):
    assert summary["starts"] == 225
    assert sum(a["share"] for a in summary["attractors"]) == pytest.approx(1.0, abs=1e-12)
    kinds = {(a["kind"], a.get("impacts_per_cycle")): a for a in summary["attractors"]}
    assert set(kinds) == {("orbit", 2.0), ("no impacts", 0.0)}
    two = kinds["orbit", 2.0]
    assert two["share"] >= 0.9 and two["share_low"] < two["share"] < two["share_high"]
    assert two["max_multiplier"] == pytest.approx(0.970, abs=2e-3)
    linear = Y * float(linear_transmissibility(W, 1.0, 1000.0, 0.1))
    assert kinds["no impacts", 0.0]["amplitude"] == pytest.approx(linear, rel=1e-3)
    ds = open_dataset(basins / "basins.nc")
    assert set(np.unique(ds["basin"].values)) == set(ds["attractor"].values) == set(range(ds.sizes["attractor"]))
    assert (basins / "basins.png").stat().st_size > 0


def test_basins_nc_selects_each_attractor_by_its_label_on_the_map(basins, summary):
    """``basin`` maps each start to a label of the coordinate ``attractor``, so xarray selects an
    attractor's row, and the map's names, by label; ``basins.csv`` gives the same labels."""
    import pandas

    ds = open_dataset(basins / "basins.nc")
    assert ds["basin"].dims == ("p0", "dp0") and ds["attractor"].dims == ("attractor",)
    for attractor in summary["attractors"]:
        row = ds.sel(attractor=attractor["id"])
        assert str(row["attractor_name"].values) == attractor["name"]
        assert float(row["attractor_share"]) == attractor["share"]
        assert int((ds["basin"] == attractor["id"]).sum()) == attractor["starts"]
    names = ds["attractor_name"].sel(attractor=ds["basin"])
    assert names.dims == ("p0", "dp0") and str(names.values[0, ISSUE_START]) == label_of(basins, summary,
                                                                                          ISSUE_START)["name"]
    table = pandas.read_csv(basins / "basins.csv")
    assert list(table.columns) == ["p0_m", "dp0_m_per_s", "attractor", "periods", "attractor_name"]
    assert (table["attractor"].values == ds["basin"].values.ravel()).all()


def test_the_map_says_how_long_each_start_took_and_that_the_budget_left_none_undecided(basins, summary):
    """The transient's length beside the map. At 1.2 w_n every start reaches one of the two
    motions well within the budget: none is undecided, and the survival fit has no plateau."""
    ds = open_dataset(basins / "basins.nc")
    periods = ds["periods"].values
    assert ds.attrs["budget_periods"] == summary["budget_periods"] == 6000
    assert periods.shape == (15, 15) and 0 < periods.max() < summary["budget_periods"]
    assert summary["undecided"] == {"starts": 0, "share": 0.0}
    fit = summary["transients"]
    assert fit["undecided"] == 0 and not fit["persists"] and fit["resolved"] == fit["at_risk"]


def test_the_boundary_is_measured(summary):
    edge = summary["boundary"]
    assert 0.0 < edge["boundary_fraction"] < 0.5
    assert 0.0 < edge["basin_entropy"] <= edge["boundary_basin_entropy"] <= math.log(2) + 1e-12


def test_the_study_had_the_fmu_check_every_attractor_and_none_disagreed(summary):
    """Every attractor confirmed by the FMU from one of its starts; no check differing while the
    FMU's trajectory and the batch engine's were together (a start whose two trajectories part in a
    chaotic transient may end apart: that is not a disagreement, see tests/test_fractions.py)."""
    checks = summary["fmu_checks"]
    assert checks["disagree"] == 0 and checks["agree"] + checks["parted"] == checks["checked"]
    assert checks["checked"] >= len(summary["attractors"]) + 10
    agreed = {c["study"] for c in checks["starts"] if c["verdict"] == "agrees"}
    assert agreed == {a["id"] for a in summary["attractors"]}


def test_a_random_sample_of_starts_marched_with_fmpy_alone_ends_where_the_map_says(basins, summary, marcher):
    ds = open_dataset(basins / "basins.nc")
    rng = np.random.default_rng(11)
    for index in rng.choice(225, size=4, replace=False):
        i, j = divmod(int(index), 15)
        p0, dp0 = float(ds["p0"].values[i]), float(ds["dp0"].values[j])
        attractor = label_of(basins, summary, int(index))
        assert ends_as_labelled(marcher, values_of(basins), W, Y, (p0, dp0, p0, 0.0), attractor,
                                int(ds["periods"].values[i, j])), (int(index), attractor["name"])


def test_an_interrupted_map_resumes_to_the_same_attractors(basins, summary, tmp_path):
    lines = (basins / "points.jsonl").read_text().splitlines(keepends=True)
    assert len(lines) == 1  # one chunk (512 starts at least) holds the whole 15 x 15 grid
    (tmp_path / "basins.json").write_text((basins / "basins.json").read_text())
    (tmp_path / "points.jsonl").write_text(lines[0][:len(lines[0]) // 2])  # killed while writing it
    assert run_cli("basins", *GRID, "--jobs", 1, "--confirm", 0, "--out", tmp_path, "--resume") == 0
    again = json.loads((tmp_path / "summary.json").read_text())
    assert [(a["name"], a["starts"]) for a in again["attractors"]] == [(a["name"], a["starts"])
                                                                       for a in summary["attractors"]]


@pytest.mark.parametrize("argv, words", [
    (["--ratio", "0"], ["--ratio 0", "allowed range (0, inf)"]),
    (["--ratio", "-1"], ["--ratio -1", "allowed range (0, inf)"]),
    (["--ratio", "1.2", "--p0=0:0.01:0"], ["--p0 0:0.01:0", "empty grid", "allowed range [1, inf)"]),
    (["--ratio", "1.2", "--dp0=0.1:-0.1:3"], ["--dp0 0.1:-0.1:3", "reversed range"]),
    (["--ratio", "1.2", "--grid", "1"], ["--grid 1", "allowed range [2, inf)"]),
    (["--ratio", "1.2", "--confirm", "-1"], ["--confirm -1", "allowed range [0, inf)"]),
    (["--ratio", "1.2", "--max-cycles", "5"], ["--max-cycles 5", "allowed range [10, inf)"]),
    (["--ratio", "1.2", "--set", "m=-1"], ["m = -1.0 is not above 0", "allowed range (0, inf] kg"]),
    (["--ratio", "1.2", "--amplitude", "0"], ["--amplitude 0", "allowed range (0, inf) m"]),
    (["--ratio", "1.2", "--device", "gpu"], ["--device gpu", "numba", "GPU"]),
    (["--ratio", "1", "--set", "C=0"], ["C = 0.0 N.s/m", "w/w_n = 1 ", "no bounded response", "allowed: C >= 3.16e-11 N.s/m"]),
    (["--ratio", "1.2", "--set", "m=0.3", "--set", f"C_eq={DEFECTIVE_C_EQ!r}"],
     ["C_eq = 242.3", "defective", "the scalar core and the FMUs take this damper", "move C_eq or R_load by a part in a million"]),
    # a main mass of 1e30 kg (its contact's slow modes merged with the fast ones by rounding), a
    # spring of 1e-20 N/m (hold steps longer than the FMU takes)
    (["--ratio", "1.2", "--set", "M=1e30"], ["M = 1e+30 kg", "closest modes 8.08e-17 of the fastest apart",
                                             "the batch studies take M <= 6.59e+13 kg (allowed range"]),
    (["--ratio", "1.2", "--set", "K=1e-20"], ["K = 1e-20 N/m", "at most 1e+07 brackets", "is 8.18e+08 s",
                                              "too slow for the FMU", "the batch studies take K >= 1.68e-19 N/m"]),
    # a heavy impact mass, and a barrier whose deflection drops out of the modes
    (["--ratio", "1.2", "--set", "m=1e20"], ["m = 1e+20 kg", "the batch studies take m <= 6.12e+14 kg"]),
    (["--ratio", "1.2", "--set", "barrier_mode=1", "--set", "K_eq=1e-30"],
     ["K_eq = 1e-30 N/m", "closed form 1 of the state off the flow", "the batch studies take K_eq >= 1.96e-29 N/m"]),
    (["--ratio", "1.2", "--set", "L_p=5e-324"],
     ["--load: the default load", "L_p = 5e-324", "allowed range (0, inf) Ohm"]),
    # what the FMU refuses itself, with a range: a beam or a damping beyond double range
    (["--ratio", "1.2", "--set", "t_b=1.7976931348623157e+308"], ["the FMU rejects", "t_b = 1.7976931348623157e+308 m",
                                                                   "leave double range", "allowed range"]),
    (["--ratio", "1.2", "--set", "C=1.7976931348623157e+308"], ["the FMU rejects", "C = 1.7976931348623157e+308 N.s/m",
                                                                 "allowed range: at least 1e-09 s"]),
    (["--ratio", "1.2", "--voltage-model", "2", "--set", "L_p=5e-324"],
     ["the FMU rejects", "L_p = 5e-324 m", "the coupled circuit's stiffness", "allowed range"]),
    (["--ratio", "1.2", "--voltage-model", "2", "--load", "5e-324"],
     ["R_load = 5e-324 Ohm is too small", "1/(R_load C_p) = inf 1/s", "allowed range [351.727, inf) Ohm"]),
])
def test_bad_basin_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "basins", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "points.jsonl").exists()


def test_an_impact_mass_of_no_weight_is_marched_and_the_fmu_agrees(tmp_path, capsys):
    """An impact mass of 1e-30 kg: its impacts give the barrier no momentum, and a contact that ends
    as it starts was marched on by the engine's modes, whose rounding started it again (the starts
    set aside, then an IndexError); now every start is marched, and the FMU agrees."""
    assert run_cli("basins", "--ratio", 1.2, "--grid", 5, "--set", "m=1e-30", "--confirm", 1, "--jobs", 1,
                   "--fmu", FMU, "--no-progress", "--out", tmp_path) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    kinds = sorted(a["kind"] for a in summary["attractors"])
    assert kinds == ["no impacts", "orbit"], kinds  # both motions of the nominal damper, none set aside
    checks = summary["fmu_checks"]
    assert checks["checked"] >= 2 and checks["agree"] == checks["checked"]


def test_a_map_with_no_entropy_writes_strict_json(tmp_path):
    """Every start undecided (a budget of 10 periods): the basin entropy has no cells to come from
    and is written null, not ``NaN``, which strict JSON readers (``jq``, a browser) refuse."""
    assert run_cli("basins", "--ratio", 1.2, "--grid", 2, "--max-cycles", 10, "--confirm", 0, "--jobs", 1,
                   "--fmu", FMU, "--no-progress", "--out", tmp_path) == 0

    def refuse(constant):
        raise ValueError(f"not strict JSON: {constant}")

    summary = json.loads((tmp_path / "summary.json").read_text(), parse_constant=refuse)
    assert summary["undecided"]["share"] == 1.0 and summary["boundary"]["basin_entropy"] is None


def test_a_process_that_ran_another_study_first_finds_the_batch_engine(tmp_path):
    """The first FMU a process loads gives it its ``piezo_fmu``; a study that ran before the basin
    map, and removed its FMU's folder, must not take the batch engine's files with it."""
    script = (f"from piezo_fmu_harness import cli\n"
              f"assert cli.main(['nominal', '--stop-time', '0.1', '--out', {str(tmp_path / 'nominal')!r}]) == 0\n"
              f"import sys; assert 'piezo_fmu.solver.batch' not in sys.modules\n"
              f"assert cli.main(['basins', '--ratio', '1.2', '--grid', '2', '--jobs', '1', '--confirm', '0',\n"
              f"                 '--no-progress', '--out', {str(tmp_path / 'basins')!r}]) == 0\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads((tmp_path / "basins" / "summary.json").read_text())["starts"] == 4
