"""The fmpy harness: nominal run, sweeps (process pool and Dask), resume, bad input.

Everything runs through ``fmus/PiezoImpactDamper.fmu``; the references are direct fmpy runs.
Short durations and small grids keep the file fast.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmu_host import assert_refused, run_cli

from piezo_fmu_harness import cli
from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.studies.sweep import command as commands
from piezo_fmu_harness.studies.sweep.analysis import PAPER_ZONES, perfectibility
from piezo_fmu_harness.fmu import FmuModel, Instance

ROOT = Path(__file__).resolve().parent.parent
METRICS = {"impact_count": "impact_count", "DI": "damping_inclination", "V_rms": "voltage_rms",
           "P_ave": "average_power"}
GRID = ["--grid", "x1=0:0.03:4", "--grid", "m=0.02:0.2:4"]
SWEEP_STOP = 0.5


@pytest.fixture(scope="session")
def fmu(tmp_path_factory) -> Path:
    """The committed FMU, or one built for this session when it is missing."""
    path = ROOT / "fmus" / "PiezoImpactDamper.fmu"
    if path.is_file():
        return path
    dest = tmp_path_factory.mktemp("fmu") / "PiezoImpactDamper.fmu"
    subprocess.run([sys.executable, "-m", "piezo_fmu.build", "--fmi", "2", "--dest", str(dest)], check=True, cwd=ROOT)
    return dest


def direct_fmpy(fmu: Path, stop_time: float, step: float, **values) -> dict:
    """The end-of-run metrics of one fresh fmpy.simulate_fmu run."""
    result = simulate_fmu(str(fmu), start_values=values, stop_time=stop_time, output_interval=step,
                          output=list(METRICS.values()))
    return {key: result[name][-1] for key, name in METRICS.items()}


def jsonl_indices(path: Path) -> list[int]:
    return [json.loads(line)["index"] for line in path.read_text().splitlines() if line.strip()]


@pytest.fixture(scope="module")
def pool_sweep(fmu, tmp_path_factory) -> Path:
    """A 4 x 4 (x1, m) sweep at 0.5 s on the default process pool."""
    out = tmp_path_factory.mktemp("pool")
    assert run_cli("sweep", *GRID, "--stop-time", SWEEP_STOP, "--jobs", 2, "--out", out, "--fmu", fmu,
                   "--no-progress") == 0
    return out



def test_results_go_to_results_in_the_working_directory_by_default(fmu, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_cli("sweep", "--grid", "m=0.02:0.2:2", "--stop-time", 0.2, "--jobs", 1, "--fmu", fmu,
                   "--no-progress") == 0
    assert run_cli("nominal", "--stop-time", 0.1, "--fmu", fmu) == 0
    assert (tmp_path / "results" / "sweep" / "points.jsonl").is_file()
    assert (tmp_path / "results" / "nominal" / "summary.json").is_file()
    parser = cli._parser()
    for command in ("nominal", "two-designs", "load-sweep", "impact-voltage", "frequency-response"):
        assert parser.parse_args([command]).out == Path("results") / command
    assert parser.parse_args(["optimize", "--param", "m=0.02:0.2"]).out == Path("results") / "optimize"

# -- nominal ---------------------------------------------------------------------------------------

def test_nominal_writes_its_files_and_its_summary_equals_a_direct_fmpy_run(fmu, tmp_path, capsys):
    stop, step = 0.5, 1e-4
    assert run_cli("nominal", "--stop-time", stop, "--out", tmp_path, "--fmu", fmu) == 0
    assert "DI (eq. 29)" in capsys.readouterr().out
    for name in ("timeseries.csv", "summary.json", "fig3a.png", "fig3b.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    summary = json.loads((tmp_path / "summary.json").read_text())
    direct = direct_fmpy(fmu, stop, step)
    assert summary["impact_count"] == direct["impact_count"] > 0
    assert summary["DI_m_per_s"] == direct["DI"] > 0
    assert summary["DI_cm_per_s"] == pytest.approx(100 * direct["DI"], rel=1e-15)
    assert summary["V_rms_V"] == direct["V_rms"]
    assert summary["P_ave_W"] == direct["P_ave"]
    assert summary["duration_s"] == stop
    assert summary["parameters"]["m"] == 0.1 and summary["parameters"]["d"] == 0.008
    assert summary["without_damper"]["impact_count"] == 0

    table = np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True)
    assert len(table) == round(stop / step) + 1
    assert np.allclose(np.diff(table["time_s"]), step)  # each column named with its unit
    assert table["impact_count"][-1] == direct["impact_count"]
    # Without the damper the main mass rings on K and C alone: the damper takes amplitude off it.
    assert np.max(table["main_displacement_m"][-2000:]) < np.max(table["main_displacement_without_damper_m"][-2000:])


# -- sweeps ----------------------------------------------------------------------------------------

def test_small_sweep_gives_the_metrics_of_single_fmpy_runs(pool_sweep, fmu):
    ds = open_dataset(pool_sweep / "sweep.nc")
    assert ds["DI"].dims == ("x1", "m") and ds["DI"].shape == (4, 4)
    assert (ds["status"] == "ok").all()
    for x1 in ds["x1"].values:
        for m in ds["m"].values:
            # A different communication step on purpose: the FMU's metrics do not depend on it.
            direct = direct_fmpy(fmu, SWEEP_STOP, 1e-3, x1=float(x1), m=float(m), d=0.008)
            point = ds.sel(x1=x1, m=m)
            for key in METRICS:
                assert float(point[key]) == pytest.approx(float(direct[key]), rel=1e-12, abs=1e-15), (x1, m, key)
    expected = perfectibility(ds["V_rms"].values, ds["DI"].values)
    assert np.array_equal(ds["perfectibility"].values, expected)
    assert np.nanmax(ds["perfectibility"].values) <= 100.0

    import pandas

    table = pandas.read_csv(pool_sweep / "sweep.csv")
    assert len(table) == 16 and list(table["index"]) == list(range(16))
    assert np.array_equal(table["DI_m_per_s"].values, ds["DI"].values.reshape(-1))
    assert np.allclose(table["DI_cm_per_s"], 100 * table["DI_m_per_s"])
    lo, hi = PAPER_ZONES["m"]
    assert table["in_paper_design_zone"].tolist() == [(lo <= m <= hi + 1e-12) and x1 <= 0.025 + 1e-12
                                                      for x1, m in zip(table["x1_m"], table["m_kg"])]
    zones = json.loads((pool_sweep / "zones.json").read_text())
    assert set(zones["zones"]) == {"DI", "V_rms", "perfectibility"}
    for name in ("DI.png", "V_rms.png", "P_ave.png", "perfectibility.png"):
        assert (pool_sweep / name).stat().st_size > 0


def test_a_sweep_ranked_by_di_ls_uses_it_for_the_vibratory_zone_and_perfectibility(pool_sweep, fmu, tmp_path):
    assert run_cli("sweep", *GRID, "--stop-time", SWEEP_STOP, "--damping", "ls", "--jobs", 2, "--out", tmp_path,
                   "--fmu", fmu, "--no-progress") == 0
    ds, eq29 = open_dataset(tmp_path / "sweep.nc"), open_dataset(pool_sweep / "sweep.nc")
    assert ds.attrs["damping_variable"] == "DI_ls" and eq29.attrs["damping_variable"] == "DI"
    for x1 in ds["x1"].values[::3]:
        for m in ds["m"].values[::3]:
            result = simulate_fmu(str(fmu), start_values={"x1": float(x1), "m": float(m), "d": 0.008},
                                  stop_time=SWEEP_STOP, output_interval=1e-3, output=["damping_inclination_ls"])
            assert float(ds["DI_ls"].sel(x1=x1, m=m)) == pytest.approx(result["damping_inclination_ls"][-1],
                                                                       rel=1e-12, abs=1e-15)
    assert np.array_equal(ds["perfectibility"].values, perfectibility(ds["V_rms"].values, ds["DI_ls"].values))
    assert np.array_equal(ds["DI"].values, eq29["DI"].values)  # eq. 29 is still there, unchanged
    zones = json.loads((tmp_path / "zones.json").read_text())
    assert set(zones["zones"]) == {"DI_ls", "V_rms", "perfectibility"}
    assert zones["zones"]["DI_ls"]["kind"] == "vibratory-based" and zones["damping_measure"] == "DI_ls"
    for name in ("DI_ls.png", "damping_measures.png", "perfectibility.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_di_ls_through_the_harness_does_not_depend_on_the_communication_step(fmu):
    model = FmuModel(fmu)
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        for values in ({}, {"m": 0.056}, {"d": 0.00743}):  # nominal, and two rows where eq. 29 misbehaves
            runs = [instance.run(values, 2.0, step) for step in (2.0, 0.2, 0.013, 1e-3)]
            assert runs[0]["DI_ls"] > 0
            for run in runs[1:]:
                assert run["DI_ls"] == pytest.approx(runs[0]["DI_ls"], rel=1e-12)
                assert run["impact_count"] == runs[0]["impact_count"]
    finally:
        instance.free()
        shutil.rmtree(unzipdir, ignore_errors=True)


def test_dask_backend_gives_the_results_of_the_process_pool(pool_sweep, fmu, tmp_path):
    import distributed
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert run_cli("sweep", *GRID, "--stop-time", SWEEP_STOP, "--scheduler", cluster.scheduler_address,
                       "--out", tmp_path, "--fmu", fmu, "--no-progress") == 0
    dask_ds, pool_ds = open_dataset(tmp_path / "sweep.nc"), open_dataset(pool_sweep / "sweep.nc")
    for key in (*METRICS, "perfectibility", "energy_dissipated", "status"):
        assert np.array_equal(dask_ds[key].values, pool_ds[key].values), key


def test_resume_after_a_killed_sweep_runs_each_point_exactly_once(fmu, tmp_path):
    # Points of 1 s at a 1e-4 s step take long enough (~0.1 s each) to kill the run midway.
    argv = [sys.executable, "-m", "piezo_fmu_harness", "sweep", *GRID, "--stop-time", "1", "--step", "1e-4",
            "--jobs", "2", "--out", str(tmp_path), "--fmu", str(fmu), "--no-progress"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    process = subprocess.Popen(argv, cwd=ROOT, env=env, start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    points = tmp_path / "points.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and process.poll() is None:
        if points.is_file() and len(jsonl_indices(points)) >= 2:
            break
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)  # the sweep and its workers, like a crash
    process.wait()
    before = points.read_text().splitlines(keepends=True)
    killed_at = len([line for line in before if line.endswith("\n")])
    assert 2 <= killed_at < 16, "the sweep was not killed midway"

    assert run_cli("sweep", *GRID, "--stop-time", 1, "--step", 1e-4, "--jobs", 2, "--out", tmp_path,
                   "--fmu", fmu, "--resume", "--no-progress") == 0
    after = points.read_text().splitlines(keepends=True)
    assert after[:killed_at] == before[:killed_at], "finished points were rewritten"
    indices = jsonl_indices(points)
    assert sorted(indices) == list(range(16)), "a point is missing or duplicated"
    ds = open_dataset(tmp_path / "sweep.nc")
    assert (ds["status"] == "ok").all() and np.isfinite(ds["DI"].values).all()


def test_a_sweep_file_in_toml_reads_like_the_command_line(fmu, tmp_path):
    from piezo_fmu_harness.spec import load_toml, parse_grid

    model = FmuModel(fmu)
    path = tmp_path / "sweep.toml"
    path.write_text('stop_time = 0.5\n[grid]\nx1 = "0:0.03:4"\nm = {start = 0.02, stop = 0.2, count = 4}\n'
                    'd = [0.004, 0.006]\n[set]\nC = 0.2\n')
    config = load_toml(model, path)
    assert config["axes"][0] == parse_grid(model, "x1=0:0.03:4")
    assert config["axes"][1] == parse_grid(model, "m=0.02:0.2:4")
    assert config["axes"][2].values == (0.004, 0.006)
    assert config["fixed"] == {"C": 0.2} and config["stop_time"] == 0.5


def test_presets_cover_the_papers_figures_4_to_9(fmu, tmp_path):
    args = cli._parser().parse_args(["sweep", "--preset", "figs4-9", "--out", str(tmp_path)])
    sweeps, panels, _ = commands.sweep_specs(args, FmuModel(fmu))
    specs = {name: spec for name, spec, _ in sweeps}
    assert panels == {"a": "x1-m", "b": "x1-d"}
    x1m, x1d = specs["x1-m"], specs["x1-d"]
    assert x1m.fixed == {"d": 0.008} and x1d.fixed == {"m": 0.1}
    assert [a.name for a in x1m.axes] == ["x1", "m"] and [a.name for a in x1d.axes] == ["x1", "d"]
    for spec in (x1m, x1d):
        assert all(len(axis) >= 31 for axis in spec.axes) and spec.stop_time == 2.0
    ranges = {axis.name: (axis.values[0], axis.values[-1]) for spec in (x1m, x1d) for axis in spec.axes}
    assert ranges == {"x1": (0.0, 0.03), "m": (0.02, 0.2), "d": (0.003, 0.01)}


# -- two designs -----------------------------------------------------------------------------------

def test_two_designs_table_puts_the_papers_numbers_beside_ours(fmu, tmp_path):
    assert run_cli("two-designs", "--stop-time", 0.5, "--step", 1e-3, "--out", tmp_path, "--fmu", fmu) == 0
    table = (tmp_path / "two_designs.md").read_text()
    for reported in ("0.6325", "3.6094", "0.1236", "0.4032", "printed 5.1", "printed 9", "**0.5 s**"):
        assert reported in table
    result = json.loads((tmp_path / "two_designs.json").read_text())
    designed = direct_fmpy(fmu, 0.5, 1e-3, x1=0.01, m=0.2, d=0.01)
    assert result["designs"]["designed"]["ours"]["V_rms_V"] == designed["V_rms"]
    assert (tmp_path / "fig10.png").stat().st_size > 0


# -- bad input: a clear error, exit status 2, nothing run -------------------------------------------

@pytest.mark.parametrize("argv, words", [
    (["--grid", "mass=0.02:0.2:4"], ["unknown parameter 'mass'", "parameters are: M, K, C, m, d"]),
    (["--grid", "x_1=0:0.03:4"], ["unknown parameter 'x_1'", "Did you mean x1?"]),
    (["--grid", "x1=0:0.03:4", "--set", "gap=0.01"], ["unknown parameter 'gap'"]),
    (["--grid", "x1=0:0.03:4", "--set", "voltage_rms=1"], ["unknown parameter 'voltage_rms'", "output"]),
    (["--grid", "x1=0.03:0:4"], ["reversed range", "x1", "START = 0.03", "STOP = 0"]),
    (["--grid", "m=0.1:0.1:4"], ["empty range", "m"]),
    (["--grid", "m=0.02:0.2:0"], ["empty range", "m", "COUNT = 0", "allowed range [1, inf)"]),
    (["--grid", "m=-0.1:0.2:4"], ["m = -0.1", "is not above 0", "modelDescription"]),
    (["--grid", "x1=0:0.03:4", "--set", "barrier_mode=2"], ["barrier_mode = 2", "above its maximum 1"]),
    (["--grid", "x1=0:0.075:4"], ["the FMU rejects", "x1 = 0.075", "x1 + L_p must be <= L"]),
    (["--grid", "x1=0:0.03"], ["expected NAME=START:STOP:COUNT"]),
    (["--grid", "x1=0:0.03:4", "--stop-time", "0"], ["--stop-time", "> 0", "allowed range (0, inf) s"]),
    (["--grid", "x1=0:0.03:4", "--step", "-1"], ["--step -1", "allowed range (0, inf) s"]),
    (["--grid", "x1=0:0.03:4", "--damping", "eq31"], ["--damping", "invalid choice: 'eq31'", "'eq29', 'ls'"]),
])
def test_bad_sweep_input_is_refused_with_exit_status_2(fmu, tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "sweep", argv, words, "--out", out, "--fmu", fmu, "--no-progress")
    assert not (out / "points.jsonl").exists()


def test_an_unwritable_output_folder_is_refused_with_exit_status_2(fmu, tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    assert run_cli("sweep", *GRID, "--out", blocker / "results", "--fmu", fmu) == 2
    assert f"--out {blocker / 'results'}: output folder is not writable" in capsys.readouterr().err
    assert run_cli("nominal", "--out", blocker / "nominal", "--fmu", fmu) == 2
    assert "output folder is not writable" in capsys.readouterr().err


def test_resuming_with_other_arguments_is_refused(pool_sweep, fmu, capsys):
    assert run_cli("sweep", *GRID, "--stop-time", 1.0, "--out", pool_sweep, "--fmu", fmu, "--resume") == 2
    assert "holds a different sweep" in capsys.readouterr().err
    assert run_cli("sweep", *GRID, "--stop-time", SWEEP_STOP, "--out", pool_sweep, "--fmu", fmu) == 2
    assert "pass --resume to finish it" in capsys.readouterr().err


def test_the_command_exits_with_status_2_on_bad_input(fmu, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "piezo_fmu_harness", "sweep", "--grid", "x1=0:0.03:4",
                           "--set", "m=-1", "--out", str(tmp_path), "--fmu", str(fmu)],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    assert done.returncode == 2
    assert "m = -1.0 is not above 0" in done.stderr


def test_zones_connected_parts_are_scipys_labels():
    from scipy import ndimage

    from piezo_fmu_harness.studies.sweep.analysis import connected_parts

    rng = np.random.default_rng(13)
    for shape in [(31, 31), (7, 9, 5), (40,), (6, 5, 4, 3)]:
        for share in (0.1, 0.3, 0.6):
            mask = rng.random(shape) < share
            labels, count = connected_parts(mask)
            expected, expected_count = ndimage.label(mask, structure=np.ones((3,) * mask.ndim))
            assert count == expected_count and np.array_equal(labels, expected), (shape, share)
