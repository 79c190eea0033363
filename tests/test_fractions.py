"""Basin fractions across a band: at each frequency the share of random starts that
reach each attractor, adding to 1, with names kept across the band, and the share the budget left
undecided, never folded into an attractor; every attractor and a random sample of starts checked by
the FMU marched with fmpy alone. The starts a 600-period cap once labelled chaotic at 1.25 w_n
reach the two-impact orbit, in the study and through fmpy alone."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fmpy_march import Marcher, ends_as_labelled, reaches
from fmu_host import DEFECTIVE_C_EQ, assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.studies.fractions.study import FractionSpec

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
W_N = math.sqrt(1000.0)
STARTS = 40
BAND = ("--ratio-min", 1.15, "--ratio-max", 1.25, "--count", 3, "--starts", STARTS, "--max-cycles", 1000, "--fmu", FMU,
        "--no-progress")


@pytest.fixture(scope="module")
def fractions(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fractions")
    assert run_cli("fractions", *BAND, "--confirm", 3, "--jobs", 2, "--out", out) == 0
    return out


@pytest.fixture(scope="module")
def summary(fractions) -> dict:
    return json.loads((fractions / "summary.json").read_text())


def test_the_summary_gives_the_marching_time_apart_from_the_fmus_checks(summary):
    assert 0 < summary["marching_s"] < summary["wall_s"] and 0 < summary["checking_s"] < summary["wall_s"]
    assert summary["marching_s"] + summary["checking_s"] <= summary["wall_s"]
    assert summary["fmu_checks"]["seconds"] == summary["checking_s"]


def test_the_fractions_add_to_one_at_every_frequency_within_their_intervals(fractions):
    ds = open_dataset(fractions / "fractions.nc")
    assert ds.sizes["omega"] == 3
    assert np.allclose(ds["fraction"].sum("attractor").values, 1.0, atol=1e-12)
    present = ds["fraction"].values > 0
    assert (ds["fraction_low"].values <= ds["fraction"].values).all()
    assert (ds["fraction"].values <= ds["fraction_high"].values).all()
    assert np.isfinite(ds["amplitude"].values[present]).all()
    assert (fractions / "fractions.png").stat().st_size > 0
    assert (fractions / "fractions.csv").read_text().startswith("omega_rad_per_s,attractor,")


def test_the_two_impact_orbit_keeps_one_name_across_the_band(fractions):
    ds = open_dataset(fractions / "fractions.nc")
    names = [str(n) for n in ds["attractor_name"].values]
    two = names.index("order 1, 2 impacts/cycle")
    assert (ds["fraction"].values[:2, two] == 1.0).all() and 0 < ds["fraction"].values[2, two] < 1.0
    amplitude = ds["amplitude"].values[:, two]
    assert np.all(np.diff(amplitude) < 0)  # one branch, its amplitude falling with the frequency


def test_every_attractor_across_the_band_and_a_start_at_every_frequency_was_checked_and_none_disagreed(summary):
    """The FMU checks one start of every attractor across the band, and ``--confirm`` (here the
    count of frequencies) random starts, one a frequency. A check may part from the study in a
    chaotic transient (at 1.25 w_n starts wander chaotically for hundreds of periods before some
    land on the orbit): then the FMU's trajectory had left the batch engine's before the study's
    answer was known. None may disagree while they were together."""
    checks = summary["fmu_checks"]
    assert checks["disagree"] == 0 and checks["agree"] + checks["parted"] == checks["checked"]
    for check in checks["starts"]:
        if check["verdict"] == "parted":
            assert check["diverged_at"] <= check["study_periods"]
    agreed = {c["study"] for c in checks["starts"] if c["verdict"] == "agrees"}
    present = {a["name"] for point in summary["by_frequency"] for a in point["attractors"]
               if a["kind"] != "undecided"}  # undecided is no attractor: it claims nothing to check
    assert agreed == present  # every attractor across the band: one start the FMU took to it
    assert {c["index"] // STARTS for c in checks["starts"]} == {0, 1, 2}  # and a start at every frequency


def test_the_budget_left_undecided_starts_undecided_with_the_transients_measured(fractions, summary):
    """At 1.25 w_n a budget of 1000 periods leaves starts on their chaotic transients: they are
    undecided, never chaotic, and the survival fit shows no plateau; the dataset says the
    undecided share, the lifetime with its interval and the survival curve."""
    ds = open_dataset(fractions / "fractions.nc")
    names = [str(n) for n in ds["attractor_name"].values]
    assert not any("chaotic" in name for name in names)
    undecided = ds["fraction"].values[:, names.index("undecided")]
    assert undecided[2] > 0 and np.allclose(ds["undecided"].values, undecided)
    assert (ds["persists"].values == 0).all()
    life = ds["lifetime"].values[2]
    assert ds["lifetime_low"].values[2] < life < ds["lifetime_high"].values[2]
    curve = ds["survival"].values[2]
    chunks = [json.loads(line) for line in (fractions / "points.jsonl").read_text().splitlines()]
    records = [r for c in chunks for r in c["starts"] if r["group"] == 2]
    periods = np.array([r["periods"] for r in records])
    resolved = np.array([r["label"] >= 0 for r in records])
    t = ds["t"].values
    expected = [np.mean(~resolved | (periods > k)) for k in t]
    assert np.allclose(curve, expected) and curve[-1] == pytest.approx(undecided[2])
    assert summary["budget_periods"] == 1000 and summary["undecided"]["starts"] == round(undecided[2] * STARTS)
    assert (fractions / "transients.png").stat().st_size > 0
    assert (fractions / "transients.csv").read_text().startswith("ratio,omega_rad_per_s,undecided,")


def test_random_starts_marched_with_fmpy_alone_end_where_the_study_says_or_are_unpredictable(fractions):
    """Each sampled start that the study resolved, marched with fmpy alone, ends on the study's
    attractor; or else its fate is shown to hang on the last bits
    (:func:`fmpy_march.ends_as_labelled`). An undecided start is claimed to go nowhere yet."""
    header = json.loads((fractions / "fractions.json").read_text())
    values = header["values"]
    u = np.random.default_rng(header["seed"]).uniform(-1.0, 1.0, (STARTS, 3))
    chunks = [json.loads(line) for line in (fractions / "points.jsonl").read_text().splitlines()]
    marcher = Marcher(FMU)
    try:
        resolved = sorted(r["index"] for c in chunks for r in c["starts"] if r["label"] >= 0)
        for index in np.random.default_rng(5).choice(resolved, size=4, replace=False):
            f, j = divmod(int(index), STARTS)
            chunk = next(c for c in chunks if f in c["frequencies"])
            record = next(r for r in chunk["starts"] if r["index"] == int(index))
            attractor = chunk["attractors"][record["label"]]
            p0 = header["span"] * u[j, 0]
            start = (p0, header["span"] * W_N * u[j, 1], p0 + 0.5 * values["d"] * u[j, 2], 0.0)
            assert ends_as_labelled(marcher, values, header["ratios"][f] * W_N, header["amplitudes"][f], start,
                                    attractor, record["periods"]), int(index)
    finally:
        marcher.close()


#: Starts of the seed-0 draw at 1.25 w_n that a 600-period cap left "chaotic". Their
#: chaotic transients are not the batch engine's (they part in the last bits), and their lengths hang
#: on the CPU type too: numpy's AVX-512 loops and OpenBLAS's kernels move the FMU's last bits. On
#: CPUs without AVX-512 the FMU's trajectories make two impacts every period from periods 427, 1274,
#: 293 and 1061; on an AVX-512 EPYC start 62 was still in its transient at 750. Each is marched
#: until it is on the orbit, within the study's budget.
ISSUE_STARTS = (0, 33, 62, 69)
#: The budget of the test's study, and of the FMU's marches.
ISSUE_BUDGET = 4000


def test_issue_31s_starts_at_1_25_end_on_the_two_impact_orbit_in_the_study_and_through_fmpy_alone(fractions):
    """Marched on (a budget of 4000 periods), the study's own starts reach the two-impact orbit
    after their chaotic transients; through the FMU marched with fmpy alone, within the same budget,
    each ends there too (section p = -0.23002 mm)."""
    from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, damper, describe, settle

    header = json.loads((fractions / "fractions.json").read_text())
    values, omega = header["values"], 1.25 * W_N
    spec = FractionSpec((1.25,), W_N, (1e-3,), values, 100, header["span"], 0)
    states = spec.states()[list(ISSUE_STARTS)]
    settled = settle(damper(values), HarmonicHold(omega, 1e-3, 0.0, spec.samples), states,
                     settings=SettleSettings(max_cycles=ISSUE_BUDGET))
    assert (settled.labels >= 0).all() and len(set(settled.labels.tolist())) == 1
    orbit = describe(settled.attractors[settled.labels[0]])
    assert orbit["kind"] == "orbit" and orbit["order"] == 1 and orbit["impacts"] == [2]
    assert orbit["sections"][0][0] == pytest.approx(-0.23002e-3, abs=1e-8)
    assert settled.periods.max() > 600  # beyond the old cap: transients, not chaos
    marcher = Marcher(FMU)
    try:
        for index, state in zip(ISSUE_STARTS, states):
            run = marcher.march(values, omega, 1e-3, state, ISSUE_BUDGET, until=lambda r: reaches(r, orbit, omega))
            assert reaches(run, orbit, omega), (index, len(run["onsets"]))
            assert (run["onsets"][-40:] == 2).all()
            assert len(run["onsets"]) > 200  # through a transient, as in the study
    finally:
        marcher.close()


def test_an_interrupted_study_resumes_to_the_same_fractions(fractions, tmp_path):
    (tmp_path / "fractions.json").write_text((fractions / "fractions.json").read_text())
    line = (fractions / "points.jsonl").read_text().splitlines(keepends=True)[0]
    (tmp_path / "points.jsonl").write_text(line[:-20])  # killed while writing its only chunk
    assert run_cli("fractions", *BAND, "--jobs", 1, "--confirm", 0, "--out", tmp_path, "--resume") == 0
    first, again = open_dataset(fractions / "fractions.nc"), open_dataset(tmp_path / "fractions.nc")
    assert list(again["attractor_name"].values) == list(first["attractor_name"].values)
    assert np.array_equal(again["fraction"].values, first["fraction"].values)


@pytest.mark.parametrize("argv, words", [
    (["--starts", "0"], ["--starts 0", "allowed range [1, inf)"]),
    (["--starts", "-5"], ["--starts -5", "allowed range [1, inf)"]),
    (["--count", "0"], ["--count 0", "allowed range [1, inf)"]),
    (["--ratio-min", "1.3", "--ratio-max", "1.1"], ["--ratio-min 1.3 is not below --ratio-max 1.1"]),
    (["--span", "0"], ["--span 0", "allowed range (0, inf) m"]),
    (["--seed", "-1"], ["--seed -1", "allowed range [0, inf)"]),
    (["--confirm", "-2"], ["--confirm -2", "allowed range [0, inf)"]),
    (["--set", "d=-0.01"], ["d = -0.01 is not above 0"]),
    (["--set", "m=0.3", "--set", f"C_eq={DEFECTIVE_C_EQ!r}"],
     ["C_eq = 242.3", "defective", "the scalar core and the FMUs take this damper", "move C_eq or R_load by a part in a million"]),
])
def test_bad_fractions_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "fractions", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "points.jsonl").exists()


def test_a_study_of_one_frequency_draws_its_shares_as_one_bar_without_a_warning(tmp_path):
    """One frequency: the shares are one stacked bar and no figure warns (a band of one frequency
    used to make matplotlib warn of identical limits, twice, and leave the shares' panel empty)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert run_cli("fractions", "--ratio-min", 1.2, "--ratio-max", 1.2, "--count", 1, "--starts", 8,
                       "--confirm", 0, "--jobs", 1, "--fmu", FMU, "--no-progress", "--out", tmp_path) == 0
    from piezo_fmu_harness.studies.fractions.figure import frequency_limits

    lo, hi = frequency_limits(np.array([1.2]))
    assert lo < 1.2 < hi and (tmp_path / "fractions.png").stat().st_size > 0
