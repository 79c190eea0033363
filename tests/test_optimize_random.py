"""``piezo-fmu optimize --objective random``: designs under a spectrum of base acceleration, each marched
on the batch engine with and without the damper over the same realizations.

- one evaluation gives what ``piezo-fmu random`` gives for the same damper, realizations and seed
  (two routes to the same numbers);
- common random numbers: a design evaluated twice gives the same bits, in a worker or here, and
  every design is marched on the same inputs (the same RMS without the damper when ``M``, ``K`` and
  ``C`` are not searched; each design its own when they are);
- a tiny search runs end to end, reports the objective's terms, and ``--resume`` finds every
  evaluation recorded and refuses a damaged one;
- bad input is refused before any work.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
from fmu_host import DEFECTIVE_C_EQ, assert_refused, run_cli
from test_optimize import FMU, log, read

#: Six realizations of 10 s after 2 s of warm-up, seed 4 (not the default: the seed must reach them).
EXCITATION = ("--realizations", 6, "--duration", 10, "--warmup", 2, "--seed", 4)
#: A tiny search over (m, d): 2 x 2 designs a generation, one generation, then the grid and the sensitivity.
SEARCH = ("optimize", "--objective", "random", "--param", "m=0.05:0.2", "--param", "d=0.004:0.012", *EXCITATION,
          "--maxiter", 1, "--popsize", 2, "--fmu", FMU, "--no-progress")


@pytest.fixture(scope="module")
def search(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("search")
    assert run_cli(*SEARCH, "--jobs", 2, "--out", out) == 0
    return out


def test_an_evaluation_gives_the_random_studys_ratio_for_the_same_damper_realizations_and_seed(search, tmp_path):
    """A design of the search (not the reference: its parameters replace the spec's) through
    ``piezo-fmu random`` with the same options: the same ratio, RMS with and without, and power."""
    record = next(r for r in log(search) if r["phase"] == "search" and r["status"] == "ok")
    spec = read(search, "optimize.json")["problem"]["random"]
    (m, d), load = record["x"], spec["values"]["R_load"]
    assert (m, d) != (spec["values"]["m"], spec["values"]["d"])
    out = tmp_path / "random"
    assert run_cli("random", "--set", f"m={m!r}", "--set", f"d={d!r}", "--load", repr(load), *EXCITATION,
                   "--confirm", 0, "--jobs", 1, "--no-progress", "--fmu", FMU, "--out", out) == 0
    (level,) = read(out, "summary.json")["levels"]
    measures = record["measures"]
    assert measures["ratio"] == pytest.approx(level["ratio"], rel=1e-12, abs=0)
    assert [measures["ratio_low"], measures["ratio_high"]] == pytest.approx(level["ratio_ci"], rel=1e-12, abs=0)
    assert measures["rms_with"] == pytest.approx(level["with"]["rms_relative"], rel=1e-12, abs=0)
    assert measures["rms_without"] == pytest.approx(level["without"]["rms_relative"], rel=1e-12, abs=0)
    assert measures["power"] == pytest.approx(level["with"]["power"], rel=1e-12, abs=0)
    assert measures["impacts_per_second"] == pytest.approx(level["with"]["impacts_per_second"], rel=1e-12, abs=0)
    assert 0 < measures["ratio"] < 1 and measures["impacts_per_second"] > 0  # the damper works here
    assert record["objective"] == record["terms"]["ratio"] == measures["ratio"]  # J is the ratio by default


def test_common_random_numbers_the_same_design_twice_the_same_bits_and_every_design_the_same_inputs(search):
    """A recorded evaluation (made in a worker) marched again here: the same bits. Every design of
    the search has the same RMS without the damper to the bit (M, K, C are not searched), while
    the designs themselves differ."""
    from piezo_fmu_harness.studies.optimize.spectrum import march_design

    spec = read(search, "optimize.json")["problem"]["random"]
    records = [r for r in log(search) if r["status"] == "ok"]
    first = records[1]
    values = {**spec["values"], **dict(zip(("m", "d"), first["x"]))}
    assert march_design(spec, values) == march_design(spec, values) == first["measures"]
    assert len({r["measures"]["rms_without"] for r in records}) == 1
    assert len({r["measures"]["rms_with"] for r in records}) == len({tuple(r["x"]) for r in records}) > 5


def test_each_design_has_its_own_without_when_the_main_oscillator_is_searched(tmp_path):
    """Searching C: the warm-up by default is the slowest design's (the smallest C), and each design
    is compared with its own main oscillator without the damper."""
    from piezo_fmu_harness.random_response.spec import SETTLED

    assert run_cli("optimize", "--objective", "random", "--param", "C=0.05:0.2", "--realizations", 2, "--duration", 2,
                   "--maxiter", 1, "--popsize", 2, "--no-grid", "--jobs", 1, "--fmu", FMU, "--no-progress",
                   "--out", tmp_path) == 0
    problem = read(tmp_path, "optimize.json")["problem"]
    M = problem["random"]["values"]["M"]
    assert problem["random"]["warmup"] == pytest.approx(math.log(1 / SETTLED) * M / 0.05, rel=1e-12)
    records = [r for r in log(tmp_path) if r["status"] == "ok"]
    assert len({r["measures"]["rms_without"] for r in records}) == len({r["x"][0] for r in records}) > 3
    # less damping, more motion without the damper
    ordered = sorted(records, key=lambda r: r["x"][0])
    assert ordered[0]["measures"]["rms_without"] > ordered[-1]["measures"]["rms_without"]


def test_a_design_the_batch_engine_cannot_march_is_rejected_not_fatal():
    from piezo_fmu_harness.fmu import FmuRunError, FmuModel
    from piezo_fmu_harness.random_response.arguments import START
    from piezo_fmu_harness.random_response.spec import RandomSpec
    from piezo_fmu_harness.studies.optimize.spectrum import march_design

    values = {**FmuModel(FMU).defaults(), **START, "m": 0.3, "C_eq": DEFECTIVE_C_EQ, "voltage_model": 0}
    spec = RandomSpec({"kind": "white", "fmin": 0.5, "fmax": 25.0}, (0.01,), values, 1, 1.0, 0.0, 0.004, 0.1)
    with pytest.raises(FmuRunError, match="the batch engine cannot march this design"):
        march_design(spec.to_dict(), values)


def test_a_tiny_search_reports_the_objectives_terms(search):
    report = read(search)
    assert report["objective"] == "random" and report["weights"] == {"ratio": 1.0, "power": 0.0}
    assert report["excitation"]["realizations"] == 6 and report["excitation"]["seed"] == 4
    reference = report["reference_design"]
    assert reference["x"] == {"m": 0.1, "d": 0.008}
    assert reference["terms"]["power"] == pytest.approx(1.0) and report["references"]["power"] > 0
    optimum = report["optimum"]
    assert optimum["terms"]["ratio"] == optimum["measures"]["ratio"] == optimum["objective"]
    assert optimum["terms"]["power"] == pytest.approx(optimum["measures"]["power"] / report["references"]["power"])
    assert optimum["objective"] <= report["grid"]["best"]["objective"] or \
        not report["grid"]["optimizer_matches_or_beats_grid"]
    text = (search / "report.md").read_text()
    for words in ("w_ratio RMS_with / RMS_without", "realizations 0-5 of seed 4", "the optimum's RMS ratio",
                  "piezo-fmu random --set m="):
        assert words in text, words
    header = (search / "evaluations.csv").read_text().splitlines()[0].split(",")
    assert {"term_ratio", "term_power", "measure_ratio", "measure_rms_without_m", "measure_power_W"} <= set(header)
    assert (search / "convergence.png").stat().st_size > 0


def test_resume_finds_every_evaluation_recorded_and_refuses_a_damaged_one(search, tmp_path, capsys):
    lines = (search / "evaluations.jsonl").read_text().splitlines(keepends=True)
    cut = tmp_path / "cut"
    cut.mkdir()
    shutil.copy(search / "optimize.json", cut)
    (cut / "evaluations.jsonl").write_text("".join(lines[:len(lines) // 3]))
    assert run_cli(*SEARCH, "--jobs", 1, "--out", cut, "--resume") == 0
    after = (cut / "evaluations.jsonl").read_text().splitlines(keepends=True)
    assert after[:len(lines) // 3] == lines[:len(lines) // 3] and len(after) == len(lines)
    assert read(cut)["optimum"] == read(search)["optimum"]
    capsys.readouterr()
    assert run_cli(*SEARCH, "--jobs", 1, "--out", cut, "--resume") == 0  # all recorded: nothing runs again
    assert f"({len(lines)} evaluations already recorded)" in capsys.readouterr().err
    assert (cut / "evaluations.jsonl").read_text().splitlines(keepends=True) == after
    damaged = [json.loads(line) for line in after]
    del damaged[2]["measures"]["rms_without"]
    (cut / "evaluations.jsonl").write_text("".join(json.dumps(r) + "\n" for r in damaged))
    assert_refused(capsys, "optimize", SEARCH[1:], ["evaluations.jsonl", "line 3", "rms_without"], "--jobs", 1,
                   "--out", cut, "--resume")


@pytest.mark.parametrize("argv, words", [
    (["--param", "p0=0:0.01"], ["--param p0=0:0.01", "the initial state is rest", "cannot be searched"]),
    (["--param", "m=0.05:0.2", "--set", "q0=0.01"], ["--set q0=0.01", "every realization starts from rest"]),
    (["--param", "m=0.05:0.2", "--voltage-model", "1"], ["--voltage-model 1", "allowed: 0", "or 2"]),
    (["--param", "C=0:1"], ["--param C=0:1", "allowed range (0, inf) N.s/m"]),
    (["--param", "m=0.05:0.2", "--weight", "amplitude=1"], ["unknown term 'amplitude'", "ratio, power"]),
    (["--param", "m=0.05:0.2", "--realizations", "0"], ["--realizations 0", "allowed range [1, inf)"]),
    (["--param", "m=0.05:0.2", "--level", "-1"], ["--level(s) -1", "allowed range (0, inf)"]),
    (["--param", "m=0.05:0.2", "--psd", "white", "--band", "5", "2"], ["fmin", "allowed"]),
])
def test_bad_random_objective_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "optimize", ["--objective", "random", *argv], words, "--out", out, "--fmu", FMU,
                   "--no-progress")
    assert not (out / "evaluations.jsonl").exists()
