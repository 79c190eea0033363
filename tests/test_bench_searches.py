"""``benchmarks/bench_searches.py``: the kernel against itself with its searches' evaluations made
twice (issue 32). Its figures rest on two facts, checked here on tiny sizes: each version's
searches call what it says (the doubled evaluation in place of the kernel's own), and the three
march the same motion, bit for bit."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_the_searches_benchmark_doubles_each_evaluation_and_marches_the_same_motion(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_searches.py"), "--rounds", "1",
                             "--ratios", "0.877,1.2", "--starts", "6", "--transient", "3", "--periods", "4"],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout)
    assert report["searches"] == {"kernel": ["contact_value", "free_values", "safe_step"],
                                  "contact": ["contact_twice", "free_values", "safe_step"],
                                  "free": ["contact_value", "free_twice", "safe_step"],
                                  "steps": ["contact_value", "free_values", "steps_twice"]}
    assert set(report["ratios"]) == {"0.877", "1.2"}
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
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_searches.py"), *arguments],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == ""
    assert said in result.stderr
