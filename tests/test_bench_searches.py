"""``benchmarks/bench_searches.py``: the kernel against itself with one piece of its searches' work
made twice. Its figures rest on two facts, checked here on tiny sizes: each version's
searches call what it says (the doubled piece in place of the kernel's own), and the four versions
march the same motion, bit for bit, from random starts and from a bifurcation diagram's clouds."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "bench_searches.py"


def bench(tmp_path, *arguments) -> dict:
    result = subprocess.run([sys.executable, str(SCRIPT), "--rounds", "1", "--starts", "6", "--periods", "4",
                             "--cache", str(tmp_path / "cache"), *arguments],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout)


def test_the_searches_benchmark_doubles_each_piece_and_marches_the_same_motion(tmp_path):
    # a diagram's points.json with one chaotic point: its start as the diagram stores it
    point = {"ratio": 0.9, "omega": 0.9 * 1000**0.5, "amplitude_Y": 1e-3, "start": [1e-3, 0.05, 0.0, 0.0],
             "start_side": 0.0, "motion": "chaotic"}
    diagram = {"values": {"voltage_model": 1, "R_load": 3.59e6}, "sweeps": [{"direction": "up", "points": [point]}]}
    (tmp_path / "points.json").write_text(json.dumps(diagram))
    for report, ratios in ((bench(tmp_path, "--ratios", "0.877,1.2", "--transient", "3"), {"0.877", "1.2"}),
                           (bench(tmp_path, "--ratios", "0.9", "--transient", "0", "--points",
                                  str(tmp_path / "points.json")), {"0.9"})):
        assert report["searches"] == {"kernel": ["contact_value", "free_values", "safe_step"],
                                      "contact": ["contact_twice", "free_values", "safe_step"],
                                      "free": ["contact_value", "free_twice", "safe_step"],
                                      "steps": ["contact_value", "free_values", "steps_twice"]}
        assert set(report["ratios"]) == ratios
        for ratio in report["ratios"].values():
            assert ratio["same_bits"] is True
            assert ratio["impacts_per_period"] > 0.0  # the searches find events: they are what is measured
            assert all(ns > 0.0 for ns in ratio["ns_per_start_period"].values())


@pytest.mark.parametrize("arguments, said", [
    (["--starts", "0"], "--starts = 0 is out of range; allowed range [1, inf)"),
    (["--periods", "-3"], "--periods = -3 is out of range; allowed range [1, inf)"),
    (["--ratios", "0.9,-1"], "--ratios = [0.9, -1.0] is out of range; allowed: one ratio or more, each in (0, inf)"),
    (["--points", "nowhere.json"], "--points = nowhere.json: no such file"),
])
def test_the_searches_benchmark_names_a_bad_option_its_value_and_what_is_allowed(tmp_path, arguments, said):
    result = subprocess.run([sys.executable, str(SCRIPT), *arguments], capture_output=True, text=True, timeout=120,
                            cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == ""
    assert said in result.stderr
