"""``piezo-fmu optimize``: differential evolution over FMU parameters, through the FMU.

A smooth objective with an optimum known in closed form, the paper's perfectibility against a
grid of the same budget, an interrupted run resumed from its log, and bad input.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
from fmu_host import assert_refused, run_cli

from piezo_fmu_harness.fmu import FmuModel, Instance

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
#: The paper's perfectibility over (m, d), a small budget: 8 x 2 designs a generation, 10 generations.
PERFECTIBILITY = ("optimize", "--param", "m=0.02:0.2", "--param", "d=0.003:0.01", "--maxiter", 10, "--popsize", 8,
                  "--seed", 3, "--fmu", FMU, "--no-progress")


def read(folder: Path, name: str = "report.json") -> dict:
    return json.loads((folder / name).read_text())


def log(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "evaluations.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def perfectibility_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("perfectibility")
    assert run_cli(*PERFECTIBILITY, "--jobs", 2, "--out", out) == 0
    return out


def test_the_optimiser_finds_a_closed_form_optimum_to_1e_3(tmp_path):
    # Without impacts (gap 1 m) the main mass at a fixed w has |X/Y|^2 = (K^2 + c^2) / ((K - a)^2 + c^2),
    # a = M w^2, c = C w, largest at K* = (a + sqrt(a^2 + 4 c^2)) / 2: maximise the transmissibility over K.
    ratio = 20.0 / math.sqrt(1000.0)  # w = 20 rad/s, as w / sqrt(K/M) of the nominal K
    assert run_cli("optimize", "--objective", "forced", "--param", "K=300:2000", "--set", "C=20", "--set", "d=1",
                   "--weight", "transmissibility=-1", "--weight", "amplitude=0", "--weight", "power=0",
                   "--ratio-min", ratio, "--ratio-max", ratio, "--count", 1, "--maxiter", 6, "--popsize", 6,
                   "--polish", "--no-grid", "--jobs", 1, "--out", tmp_path, "--fmu", FMU, "--no-progress") == 0
    band = read(tmp_path, "optimize.json")["problem"]["band"]
    omega = band["ratios"][0] * band["natural_rad_per_s"]
    a, c = omega**2, 20.0 * omega
    k_star = (a + math.sqrt(a * a + 4 * c * c)) / 2
    report = read(tmp_path)
    assert report["optimum"]["x"]["K"] == pytest.approx(k_star, rel=1e-3)
    peak = math.sqrt((k_star**2 + c * c) / ((k_star - a) ** 2 + c * c))
    assert report["optimum"]["terms"]["transmissibility"] == pytest.approx(peak, rel=1e-4)
    assert report["optimum"]["objective"] == -report["optimum"]["terms"]["transmissibility"]


def test_on_the_papers_perfectibility_it_matches_or_beats_the_grid_of_the_same_budget(perfectibility_run):
    report = read(perfectibility_run)
    grid, search = report["grid"], report["search"]
    assert grid["evaluations"] <= search["evaluations"] < (grid["points_per_axis"] + 1) ** 2
    assert report["optimum"]["objective"] <= grid["best"]["objective"]
    assert grid["optimizer_matches_or_beats_grid"] is True
    # J is eq. 31 with the reference design's DI and V_rms as the maxima, measured by the FMU.
    optimum, references = report["optimum"], report["references"]
    assert optimum["objective"] == pytest.approx(-100 * (0.5 * optimum["measures"]["DI"] / references["DI"]
                                                         + 0.5 * optimum["measures"]["V_rms"] / references["V_rms"]))
    assert report["reference_design"]["objective"] == pytest.approx(-100.0)
    model = FmuModel(FMU)
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        direct = instance.run(optimum["x"], 2.0, 1e-3)
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)
    assert direct["DI"] == pytest.approx(optimum["measures"]["DI"], rel=1e-12)
    assert direct["V_rms"] == pytest.approx(optimum["measures"]["V_rms"], rel=1e-12)
    names = [row["name"] for row in report["sensitivity"]["parameters"]]
    assert names == ["m", "d"]
    records = log(perfectibility_run)
    assert sum(r["phase"] == "grid" for r in records) == grid["evaluations"]
    assert {r["phase"] for r in records} == {"reference", "search", "grid", "sensitivity"}
    for name in ("report.md", "evaluations.csv", "convergence.png"):
        assert (perfectibility_run / name).stat().st_size > 0


def test_an_interrupted_optimisation_resumes_from_its_log_and_loses_nothing(perfectibility_run, tmp_path):
    shutil.copy(perfectibility_run / "optimize.json", tmp_path)
    lines = (perfectibility_run / "evaluations.jsonl").read_text().splitlines(keepends=True)
    kept = lines[:len(lines) // 3]  # killed a third of the way through the search
    (tmp_path / "evaluations.jsonl").write_text("".join(kept))
    assert run_cli(*PERFECTIBILITY, "--jobs", 2, "--out", tmp_path, "--resume") == 0
    after = (tmp_path / "evaluations.jsonl").read_text().splitlines(keepends=True)
    assert after[:len(kept)] == kept  # nothing written before is touched
    assert len(after) == len(lines)  # and nothing evaluated twice
    resumed, first = read(tmp_path), read(perfectibility_run)
    assert resumed["optimum"] == first["optimum"] and resumed["grid"] == first["grid"]


@pytest.mark.parametrize("argv, words", [
    ([], ["--param NAME=LO:HI is required"]),
    (["--param", "m=0.2:0.02"], ["--param m=0.2:0.02", "reversed range for m", "LO = 0.2"]),
    (["--param", "mass=0.02:0.2"], ["unknown parameter 'mass'"]),
    (["--param", "m=0.02"], ["--param m=0.02", "expected NAME=LO:HI"]),
    (["--param", "m=-1:0.2"], ["m = -1.0 is not above 0"]),
    (["--param", "barrier_mode=0:1"], ["barrier_mode is an Integer parameter"]),
    (["--param", "m=0.02:0.2", "--set", "m=0.1"], ["m is both searched (--param) and fixed (--set)"]),
    (["--param", "x1=0:0.075"], ["the bounds of --param", "the FMU rejects", "x1 + L_p must be <= L"]),
    (["--param", "m=0.02:0.2", "--weight", "power=1"], ["--weight power=1", "unknown term 'power'", "DI, V_rms"]),
    (["--param", "m=0.02:0.2", "--weight", "DI=0", "--weight", "V_rms=0"], ["every weight is 0"]),
    (["--param", "m=0.02:0.2", "--reference", "DI=-1"], ["--reference DI=-1", "allowed range (0, inf)"]),
    (["--param", "m=0.02:0.2", "--maxiter", "0"], ["--maxiter 0", "allowed range [1, inf)"]),
    (["--param", "m=0.02:0.2", "--sensitivity-step", "0.9"], ["--sensitivity-step 0.9", "allowed range (0, 0.5]"]),
    (["--param", "m=0.02:0.2", "--objective", "fast"], ["--objective", "invalid choice: 'fast'"]),
    (["--objective", "forced", "--param", "p0=0:0.01"], ["--param p0=0:0.01", "initial state"]),
    (["--objective", "forced", "--param", "m=0.02:0.2", "--count", "1"], ["--count 1 needs --ratio-min = --ratio-max"]),
    (["--objective", "forced", "--param", "m=0.02:0.2", "--amplitude", "-1"], ["--amplitude -1", "(0, inf) m"]),
])
def test_bad_optimize_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "optimize", argv, words, "--out", out, "--fmu", FMU, "--no-progress")
    assert not (out / "evaluations.jsonl").exists()


def test_the_forced_objective_can_weigh_the_worse_of_the_up_and_down_stable_responses(tmp_path):
    # At 1.15-1.2 w_n two stable motions coexist (tests/test_basins.py): the sweeps up and down from
    # rest may end on different ones, and the worst term sees the larger. 32 communication steps a
    # period (not 64) halve the FMU's work; what is tested, how the term combines the sweeps, is the same.
    assert run_cli("optimize", "--objective", "forced", "--param", "m=0.095:0.105", "--weight", "worst=1",
                   "--weight", "amplitude=0", "--weight", "power=0", "--ratio-min", 1.15, "--ratio-max", 1.2,
                   "--count", 2, "--samples", 32, "--maxiter", 1, "--popsize", 1, "--no-grid",
                   "--sensitivity-step", 0.5, "--jobs", 2, "--fmu", FMU, "--no-progress", "--out", tmp_path) == 0
    records = [r for r in log(tmp_path) if r.get("status") == "ok" and r.get("terms")]
    assert records
    for record in records:
        measures, terms = record["measures"], record["terms"]
        without = measures.get("amplitude_without") or read(tmp_path)["references"]["amplitude_without"]
        assert terms["worst"] == pytest.approx(max(measures["amplitude"], measures["amplitude_down"]) / without)
        assert record["objective"] == pytest.approx(terms["worst"])
    # Two motions, not the rounding of one: some design's sweeps end on orbits 10% apart or more.
    assert any(abs(r["measures"]["amplitude_down"] / r["measures"]["amplitude"] - 1.0) > 0.1 for r in records)
