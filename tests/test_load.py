"""The harness's load sweep and single-impact voltages, through the FMU with fmpy.

References are direct fmpy runs of the same FMU; short durations and few loads keep it fast.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmu_host import assert_refused, run_cli

from piezo_fmu_harness.fmu import FmuModel
from piezo_fmu_harness.studies.load.sweep import find_optimum

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
HARNESS = ROOT / "src" / "piezo_fmu_harness"
STOP = 0.3
#: 1e5 .. 1e8 Ohm, five loads: brackets the optimum (about 3 MOhm) with two loads on each side.
BRACKET = ["--r-min", 1e5, "--r-max", 1e8, "--count", 5]
ENERGIES = ("harvested_energy", "harvested_energy_left", "harvested_energy_right", "impact_count")


def read_csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


def rows_of(table: np.ndarray, model: int) -> np.ndarray:
    return table[table["voltage_model"] == model]


@pytest.fixture(scope="module")
def bracket(tmp_path_factory) -> Path:
    """Models 1 and 2 at five loads, 0.3 s each, on two worker processes, with the impact figures."""
    out = tmp_path_factory.mktemp("load")
    assert run_cli("load-sweep", *BRACKET, "--models", "1,2", "--stop-time", STOP, "--jobs", 2,
                   "--out", out, "--fmu", FMU) == 0
    return out


def test_the_load_sweep_writes_its_files(bracket, capsys):
    for name in ("load_sweep.csv", "load_sweep.json", "load_sweep.md", "load_sweep.png", "impact.json"):
        assert (bracket / name).stat().st_size > 0, name
    summary = json.loads((bracket / "load_sweep.json").read_text())
    assert summary["duration_s"] == STOP and summary["failed_points"] == {}
    assert summary["loads_ohm"][0] == 1e5 and summary["loads_ohm"][-1] == 1e8 and len(summary["loads_ohm"]) == 5
    assert set(summary["models"]) == {"1", "2"}
    table = read_csv(bracket / "load_sweep.csv")
    assert len(table) == 10
    impact = json.loads((bracket / "impact.json").read_text())
    assert set(impact["loads"]) == {"paper's", "optimum"}
    for entry in impact["loads"].values():
        assert Path(entry["figure"]).stat().st_size > 0 and Path(entry["csv"]).stat().st_size > 0
        assert set(entry["models"]) == {"0", "1", "2"}
    text = (bracket / "load_sweep.md").read_text()
    assert "R_opt ~ 1/(omega_c C_p)" in text and "**0.3 s**" in text


def test_each_point_equals_a_direct_fmpy_run(bracket):
    table = read_csv(bracket / "load_sweep.csv")
    for row in table:
        # Another communication step on purpose: the FMU's end-of-run values do not depend on it.
        direct = simulate_fmu(str(FMU), start_values={"R_load": float(row["R_load_ohm"]),
                                                      "voltage_model": int(row["voltage_model"])},
                              stop_time=STOP, output_interval=1e-3, output=list(ENERGIES))[-1]
        where = (int(row["voltage_model"]), float(row["R_load_ohm"]))
        assert row["impact_count"] == direct["impact_count"] > 0, where
        for name in ENERGIES[:3]:
            assert row[f"{name}_J"] == pytest.approx(direct[name], rel=1e-12), (where, name)
        assert row["harvested_energy_J"] > 0
        assert row["energy_per_impact_J"] == pytest.approx(direct["harvested_energy"] / direct["impact_count"],
                                                           rel=1e-12), where
        assert row["average_power_W"] == pytest.approx(direct["harvested_energy"] / STOP, rel=1e-12), where


def test_the_optimum_is_the_best_point_inside_the_range_beside_the_estimate(bracket):
    summary = json.loads((bracket / "load_sweep.json").read_text())
    table = read_csv(bracket / "load_sweep.csv")
    start = FmuModel(FMU).defaults()
    for model, entry in summary["models"].items():
        rows = rows_of(table, int(model))
        # The estimate is 1 / (omega_c C_p) with C_p = eps33 W_p L_p / t_p of the FMU's start values.
        capacitance = start["eps33"] * start["W_p"] * start["L_p"] / start["t_p"]
        assert entry["patch_capacitance_F"] == pytest.approx(capacitance, rel=1e-12)
        assert entry["R_opt_estimate_ohm"] == pytest.approx(
            1 / (entry["contact_frequency_rad_per_s"] * capacitance), rel=1e-12)
        for key in ("energy_per_impact_J", "average_power_W"):
            optimum = entry["optimum"][key]
            best = int(np.argmax(rows[key]))
            assert optimum["index"] == best and 0 < best < len(rows) - 1, (model, key)
            assert optimum["R_ohm"] == rows["R_load_ohm"][best]
            assert optimum["value"] == pytest.approx(rows[key].max(), rel=1e-10)
            assert optimum["bracketed"]
            assert rows["R_load_ohm"][best - 1] < optimum["R_refined_ohm"] < rows["R_load_ohm"][best + 1]
            assert optimum["value_refined"] >= optimum["value"]
            # The measured optimum lies near the estimate (within a factor of 2).
            assert 0.5 < optimum["R_refined_ohm"] / entry["R_opt_estimate_ohm"] < 2, (model, key)


def test_power_rises_with_the_load_below_the_optimum_and_falls_above(bracket):
    table = read_csv(bracket / "load_sweep.csv")
    for model in (1, 2):
        rows = rows_of(table, model)
        for key in ("energy_per_impact_J", "average_power_W"):
            best = int(np.argmax(rows[key]))
            assert np.all(np.diff(rows[key][:best + 1]) > 0), (model, key)
            assert np.all(np.diff(rows[key][best:]) < 0), (model, key)


def test_energy_per_impact_follows_the_small_and_large_load_limits(tmp_path):
    """Small R: V ~ R chi delta', so the energy grows as R; large R: V ~ (chi/C_p) delta, as 1/R."""
    assert run_cli("load-sweep", "--r-min", 1e2, "--r-max", 1e10, "--count", 9, "--models", 1, "--stop-time", STOP,
                   "--jobs", 1, "--no-impact", "--out", tmp_path, "--fmu", FMU) == 0
    summary = json.loads((tmp_path / "load_sweep.json").read_text())
    rows = rows_of(read_csv(tmp_path / "load_sweep.csv"), 1)
    per_ohm = rows["energy_per_impact_J"] / rows["R_load_ohm"]
    assert per_ohm[1] == pytest.approx(per_ohm[0], rel=1e-3)  # the small-R limit E ~ R
    times_ohm = rows["energy_per_impact_J"] * rows["R_load_ohm"]
    assert times_ohm[-1] == pytest.approx(times_ohm[-2], rel=2e-2)  # the large-R limit E ~ 1/R
    slopes = summary["models"]["1"]["slopes_energy_per_impact"]
    assert slopes["low_R"] == pytest.approx(1.0, abs=1e-3) and slopes["high_R"] == pytest.approx(-1.0, abs=2e-2)
    assert not (tmp_path / "impact.json").exists()


def test_find_optimum_refines_a_sampled_peak_and_leaves_an_edge_alone():
    loads = [1e3, 1e4, 1e5, 1e6]
    # ln(value) a parabola in log10 R with its vertex at 10**4.3: recovered exactly.
    values = [np.exp(-(np.log10(r) - 4.3) ** 2) for r in loads]
    optimum = find_optimum(loads, values)
    assert optimum["index"] == 1 and optimum["R_refined_ohm"] == pytest.approx(10 ** 4.3, rel=1e-9)
    assert optimum["value_refined"] == pytest.approx(1.0, rel=1e-9)
    edge = find_optimum(loads, [1.0, 2.0, 3.0, 4.0])
    assert edge["index"] == 3 and not edge["bracketed"] and edge["R_refined_ohm"] is None


# -- a single impact -------------------------------------------------------------------------------

def test_the_single_impact_peak_is_the_fmus_own_impact_voltage(tmp_path):
    assert run_cli("impact-voltage", "--load", 52e3, "--models", "0,1", "--out", tmp_path, "--fmu", FMU) == 0
    result = json.loads((tmp_path / "impact.json").read_text())
    entry = result["loads"]["52 kOhm"]
    assert Path(entry["figure"]).stat().st_size > 0
    assert result["sampling_step_s"] == 1e-6
    series = read_csv(Path(entry["csv"]))
    side = result["barrier"]
    for model, expected_peak in (("0", 1800), ("1", 10)):
        e = entry["models"][model]
        peak = np.max(np.abs(series[f"voltage_model{model}_V"]))
        assert e["peak_voltage_sampled_V"] == pytest.approx(peak, rel=1e-11) and peak > expected_peak
        # Sampled every microsecond, the peak is the FMU's own eq. 28 peak of the impact.
        assert peak == pytest.approx(e["last_impact_voltage_V"], rel=1e-6), model
        assert e["impacts_in_window"] == 1
    # Model 0 is quasi-static: V / delta is the constant k_V throughout the contact.
    contact = series["deflection_model0_m"] > 1e-6
    ratio = series["voltage_model0_V"][contact] / series["deflection_model0_m"][contact]
    assert np.ptp(ratio) < 1e-9 * ratio.mean() and ratio.mean() == pytest.approx(6.83e6, rel=1e-2)
    # Model 1 at 52 kOhm follows the deflection rate: it changes sign within the contact.
    inside = series["deflection_model1_m"] > 0
    assert series["voltage_model1_V"][inside].max() > 0 > series["voltage_model1_V"][inside].min()
    # The fine samples are those of a plain fmpy run over the same span.
    stop = series["time_s"][-1]
    direct = simulate_fmu(str(FMU), start_values={"voltage_model": 1}, stop_time=stop, output_interval=1e-5,
                          output=[f"voltage_{side}"])
    index = np.searchsorted(series["time_s"], direct["time"] - 1e-12)
    keep = (index < len(series)) & (direct["time"] >= series["time_s"][0])
    matched = series["voltage_model1_V"][index[keep]]
    assert np.allclose(series["time_s"][index[keep]], direct["time"][keep], rtol=0, atol=1e-12)
    assert keep.sum() > 100
    assert np.allclose(matched, direct[f"voltage_{side}"][keep], rtol=1e-9, atol=1e-9)


# -- bad input -------------------------------------------------------------------------------------

@pytest.mark.parametrize("command, argv, words", [
    ("load-sweep", ["--r-min", "1e9", "--r-max", "1e3"], ["--r-min 1e+09", "--r-max 1000", "reversed range", "R_load"]),
    ("load-sweep", ["--r-min", "1e6", "--r-max", "1e6"], ["empty range", "R_load"]),
    ("load-sweep", ["--r-min", "0"], ["--r-min 0", "R_load = 0 Ohm", "allowed range (0, inf) Ohm"]),
    ("load-sweep", ["--r-max", "-5"], ["--r-max -5", "R_load = -5 Ohm", "> 0"]),
    ("load-sweep", ["--models", "3"], ["--models 3", "voltage_model = 3 is", "above its maximum 2", "[0, 2]"]),
    ("load-sweep", ["--models", "1,x"], ["--models 1,x", "voltage_model = 'x' is not a number"]),
    ("load-sweep", ["--models", "0"], ["voltage_model = 0", "harvests no energy", "1 or 2"]),
    ("load-sweep", ["--count", "2"], ["--count 2", "at least 3 loads", "allowed range [3, inf)"]),
    ("load-sweep", ["--set", "R_load=1e6"], ["--set R_load", "--r-min"]),
    ("load-sweep", ["--models", "2", "--r-min", "100"], ["the FMU rejects", "voltage_model = 2, R_load = 100",
                                                        "R_load"]),
    ("impact-voltage", ["--load", "0"], ["--load 0", "R_load = 0 Ohm", "allowed range (0, inf) Ohm"]),
    ("impact-voltage", ["--models", "0,7"], ["voltage_model = 7 is", "above its maximum 2"]),
    ("impact-voltage", ["--stop-time", "0.01"], ["--stop-time 0.01 s", "no complete impact within 0.01 s"]),
])
def test_bad_input_is_refused_with_exit_status_2(tmp_path, capsys, command, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, command, argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "load_sweep.json").exists() and not (out / "impact.json").exists()


# -- the harness knows the FMU only ----------------------------------------------------------------

def test_the_harness_never_imports_the_core():
    for path in sorted(HARNESS.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            assert not any(name.split(".")[0] == "piezo_fmu" for name in names), (path.name, names)
    modules = [".".join(("piezo_fmu_harness",) + p.relative_to(HARNESS).with_suffix("").parts).removesuffix(".__init__")
               for p in sorted(HARNESS.rglob("*.py")) if p.stem != "__main__" and "__pycache__" not in p.parts]
    code = (f"import sys, importlib\nfor m in {modules!r}: importlib.import_module(m)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'piezo_fmu'))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout
