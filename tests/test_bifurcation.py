"""The bifurcation diagram: section samples and impacts per cycle, up and down, on
the batch engine, a point called chaotic only where its motion persists (shown through the FMU too:
it persists over a march twice the budget and parts from a neighbour start at a positive rate), a
sample of points checked through the FMU; bad input refused before any run."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from fmpy_march import Marcher, nudged, settled
from fmu_host import DEFECTIVE_C_EQ, assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.studies.bifurcation.study import CLASSES, CLOUD

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"


@pytest.fixture(scope="module")
def diagram(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bifurcation")
    assert run_cli("bifurcation", "--ratio-min", 0.98, "--ratio-max", 1.02, "--count", 3, "--max-cycles", 400,
                   "--jobs", 3, "--out", out, "--fmu", FMU) == 0
    return out


def test_each_point_has_its_section_samples_and_its_class(diagram):
    ds = open_dataset(diagram / "bifurcation.nc")
    assert ds.sizes["direction"] == 2 and ds.sizes["omega"] == 3
    motion = ds["motion"].values
    assert set(np.unique(motion)) <= set(CLASSES)
    samples = np.isfinite(ds["p_section"].values).sum(axis=-1)
    for where in np.ndindex(motion.shape):
        if motion[where] == "periodic":
            assert 1 <= samples[where] <= 4  # an orbit of order n gives its n samples
            assert np.isnan(ds["lyapunov_exponent"].values[where])
        else:
            assert samples[where] == 40 and np.isfinite(ds["lyapunov_exponent"].values[where])
            assert ds["periods"].values[where] == ds.attrs["budget_periods"]
    # At w_n the default damper's motion is chaotic, sweeping either way: its cloud persists.
    assert (ds["motion"].sel(omega=ds["omega"].values[1]).values == "chaotic").all()
    summary = json.loads((diagram / "summary.json").read_text())
    assert sum(c["count"] for d in summary["classes"].values() for c in d.values()) == 6
    assert (diagram / "bifurcation.png").stat().st_size > 0


def test_the_csv_gives_each_sample_with_one_ratio_column(diagram):
    import pandas

    table = pandas.read_csv(diagram / "bifurcation.csv")
    assert list(table.columns) == ["direction", "omega_rad_per_s", "sample", "p_section_m", "ratio", "impacts_per_cycle",
                                   "motion"]
    ds = open_dataset(diagram / "bifurcation.nc")
    assert len(table) == int(np.isfinite(ds["p_section"].values).sum())
    expected = ds["ratio"].sel(omega=table["omega_rad_per_s"].values, method="nearest").values
    assert np.allclose(table["ratio"].values, expected, rtol=1e-15, atol=0)


def test_the_summary_gives_the_work_of_the_sweeps_and_of_the_clouds(diagram):
    """``summary.json`` says where the start-periods went: a point on no orbit marched its own
    trajectory through the budget, and a cloud that persisted kept all its companions to the end."""
    summary = json.loads((diagram / "summary.json").read_text())
    points = [p for sweep in json.loads((diagram / "points.json").read_text())["sweeps"] for p in sweep["points"]]
    budget, work = summary["budget_periods"], summary["start_periods"]
    unresolved = [p for p in points if p["motion"] != "periodic"]
    persisted = [p for p in unresolved if p["transients"]["persists"]]
    assert persisted and work["clouds"] == sum(p["cloud_start_periods"] for p in unresolved)
    assert all(p["cloud_start_periods"] >= CLOUD * budget for p in persisted)
    assert all(p["start_periods"] >= budget for p in unresolved)
    assert work["sweeps"] == sum(p["start_periods"] for p in points)
    assert summary["cpu_s"] == pytest.approx(sum(p["cpu_seconds"] for p in points))


def test_the_fmu_checked_every_kind_of_motion_the_diagram_shows_and_none_disagreed_in_a_time_of_its_own(diagram):
    summary = json.loads((diagram / "summary.json").read_text())
    checks = summary["fmu_checks"]
    assert checks["disagree"] == 0 and checks["agree"] + checks["parted"] == checks["checked"]
    shown = {kind for classes in summary["classes"].values() for kind in classes if not kind.startswith("undecided")}
    assert {c["motion"] for c in checks["points"] if c["verdict"] == "agrees"} == shown  # undecided claims nothing
    assert checks["seconds"] == summary["checking_s"] and summary["marching_s"] + summary["checking_s"] <= summary["wall_s"]


def test_a_point_called_chaotic_persists_twice_the_budget_and_parts_from_a_neighbour_through_the_fmu(diagram):
    """Chaos is a claim that needs evidence. Every chaotic point's cloud persisted and its
    exponent's interval lies above 0; through the FMU marched with fmpy alone from the point's start,
    the motion never settles over twice the budget, and a start moved by 1e-9 of itself (of ``Y``
    in both displacements for a start at rest) parts from it at a positive rate, to the motion's own
    size."""
    saved = json.loads((diagram / "points.json").read_text())
    points = [p for sweep in saved["sweeps"] for p in sweep["points"]]
    chaotic = [p for p in points if p["motion"] == "chaotic"]
    assert chaotic
    for p in points:
        if p["motion"] != "periodic":
            assert (p["motion"] == "chaotic") == (p["transients"]["persists"] and p["exponent_low"] > 0)
            assert p["transients"]["starts"] == CLOUD + 1  # the point's own trajectory and its cloud
    budget = json.loads((diagram / "summary.json").read_text())["budget_periods"]
    point = chaotic[0]
    values = saved["values"]
    marcher = Marcher(FMU)
    try:
        start = np.array(point["start"])
        run = marcher.march(values, point["omega"], point["amplitude_Y"], start, 2 * budget)
        windows = [{"sections": run["sections"][k - 40:k]} for k in range(budget, 2 * budget + 1, 100)]
        assert not any(settled(w, point["omega"]) for w in windows)
        assert (run["onsets"][budget:] > 0).mean() > 0.1  # still impacting to the end
        moved = marcher.march(values, point["omega"], point["amplitude_Y"], nudged(start, 1e-9, point["amplitude_Y"]),
                              100)
        scale = np.array([1.0, 1.0 / point["omega"], 1.0, 1.0 / point["omega"]])
        gap = np.abs((moved["sections"] - run["sections"][:100]) * scale).max(axis=1)
        assert gap.max() > 1e-4
        early = gap[: int(np.argmax(gap > 1e-6))]
        assert len(early) > 1 and math.log(early[-1] / early[0]) / (len(early) - 1) > 0.05
    finally:
        marcher.close()


def test_one_process_draws_the_diagram_the_process_pool_draws(diagram, tmp_path):
    """The chains and the clouds are tasks of their own, finished in whatever order the workers
    take them: one process, running them one after the other, gives every point the same."""
    from piezo_fmu_harness.engine import InProcess
    from piezo_fmu_harness.periodic.band import FrequencySpec, Settings
    from piezo_fmu_harness.studies.bifurcation import chains

    pool = json.loads((diagram / "points.json").read_text())
    ds = open_dataset(diagram / "bifurcation.nc")
    up = pool["sweeps"][0]["points"]
    spec = FrequencySpec(tuple(float(r) for r in ds["ratio"].values), up[0]["omega"] / up[0]["ratio"],
                         up[0]["amplitude_Y"], None, pool["values"], 0.0, Settings(**json.loads(ds.attrs["settings"])))
    alone = chains.run({**chains.plain(spec, "cpu"), "fmu_guid": None}, InProcess(None), tmp_path, {}, True, False)
    assert [len(s["points"]) for s in alone] == [len(s["points"]) for s in pool["sweeps"]] == [3, 3]
    for a, b in zip(pool["sweeps"], alone):
        for p, q in zip(a["points"], b["points"]):
            p.pop("cpu_seconds"), q.pop("cpu_seconds")
            assert p == q


def persistence(*argv) -> tuple[int, dict]:
    """``tools/persistence.py`` in a fresh process: its exit status and its report."""
    import subprocess

    done = subprocess.run([sys.executable, str(ROOT / "tools" / "persistence.py"), *map(str, argv), "--no-progress"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, json.loads(done.stdout)


def test_every_point_called_chaotic_persists_under_a_march_twice_as_long(diagram):
    """The check of a run by ``tools/persistence.py``: each chaotic point's own trajectory,
    marched again from its start for twice the budget, still reaches no orbit."""
    status, report = persistence(diagram)
    (folder,) = report["folders"]
    points = [p for s in json.loads((diagram / "points.json").read_text())["sweeps"] for p in s["points"]]
    assert folder["claims"] == sum(p["motion"] in ("chaotic", "quasi-periodic") for p in points) > 0
    assert folder["marched"] == 2 * folder["budget"] == 800
    assert folder["start_periods"] >= folder["claims"] * 800  # each marched to the end
    assert folder["persisted"] == folder["claims"] and folder["resolved"] == [] and status == 0


def test_the_persistence_check_finds_a_claim_that_reaches_an_orbit(diagram, tmp_path):
    """The check can fail: a periodic point relabelled chaotic is found reaching its orbit, at the
    period the diagram says, and the exit status says a claim did not hold."""
    copy = tmp_path / "diagram"
    copy.mkdir()
    for name in ("points.json", "bifurcation.nc", "summary.json"):
        (copy / name).write_bytes((diagram / name).read_bytes())
    saved = json.loads((copy / "points.json").read_text())
    point = next(p for s in saved["sweeps"] for p in s["points"] if p["motion"] == "periodic")
    point["motion"] = "chaotic"
    (copy / "points.json").write_text(json.dumps(saved))
    status, report = persistence(copy)
    (folder,) = report["folders"]
    wrong = [r for r in folder["resolved"] if r["ratio"] == point["ratio"]]
    assert status == 1 and len(wrong) == 1 and wrong[0]["resolved_at"] == point["periods"]
    assert wrong[0]["reached"]["order"] == point["order"]


@pytest.mark.parametrize("argv, words", [
    (["--ratio-min", "0"], ["--ratio-min 0", "allowed range (0, inf)"]),
    (["--ratio-min", "1.2", "--ratio-max", "1.1"], ["--ratio-min 1.2", "reversed range"]),
    (["--count", "1"], ["--count 1", "allowed range [2, inf)"]),
    (["--set", "m=-1"], ["m = -1.0 is not above 0", "allowed range (0, inf] kg"]),
    (["--confirm", "-1"], ["--confirm -1", "allowed range [0, inf)"]),
    (["--jobs", "0"], ["--jobs 0", "worker", "allowed range [1, inf)"]),
    (["--set", "m=0.3", "--set", f"C_eq={DEFECTIVE_C_EQ!r}"],
     ["C_eq = 242.3", "defective", "the scalar core and the FMUs take this damper", "move C_eq or R_load by a part in a million"]),
    (["--device", "gpu"], ["--device gpu", "numba", "GPU"]),
])
def test_bad_bifurcation_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "bifurcation", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "bifurcation.nc").exists()


def test_the_diagram_takes_every_worker_it_is_given(tmp_path, monkeypatch):
    """The chains keep two workers busy; the clouds and the FMU's checks are tasks of their own, so
    ``--jobs 3`` gives the diagram three (it took two at most before)."""
    from piezo_fmu_harness import checks

    asked = []
    make_backend = checks.make_backend
    monkeypatch.setattr(checks, "make_backend", lambda args, model, unzipdir, jobs: asked.append(jobs) or make_backend(
        args, model, unzipdir, jobs))
    assert run_cli("bifurcation", "--ratio-min", 1.1, "--ratio-max", 1.2, "--count", 2, "--max-cycles", 40,
                   "--confirm", 0, "--jobs", 3, "--no-progress", "--out", tmp_path, "--fmu", FMU) == 0
    assert asked == [3]


@pytest.mark.parametrize("quiet", [False, True])
def test_the_sweeps_show_a_progress_bar_unless_told_not_to(tmp_path, capsys, monkeypatch, quiet):
    """A frequency a task: on a terminal, the bar counts the points of both sweeps as they are done
   ; ``--no-progress`` silences it."""
    argv = ["--ratio-min", 1.1, "--ratio-max", 1.2, "--count", 2, "--max-cycles", 40, "--confirm", 0, "--jobs", 1,
            "--out", tmp_path] + (["--no-progress"] if quiet else [])
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert run_cli("bifurcation", *argv) == 0
    err = capsys.readouterr().err
    assert ("bifurcation: 100%" in err and "4/4" in err) != quiet, err
