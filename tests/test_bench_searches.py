"""``benchmarks/bench_searches.py``: the kernel against itself with its searches' evaluations made
twice (issue 32). Its figures rest on two facts, checked here on tiny sizes: each version's
searches call what it says (the doubled evaluation in place of the kernel's own), and the three
march the same motion, bit for bit."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_searches_benchmark_doubles_each_evaluation_and_marches_the_same_motion(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_searches.py"), "--rounds", "1",
                             "--ratios", "0.877,1.2", "--starts", "6", "--transient", "3", "--periods", "4"],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout)
    assert report["searches"] == {"kernel": ["contact_value", "free_values"],
                                  "contact": ["contact_twice", "free_values"],
                                  "free": ["contact_value", "free_twice"]}
    assert set(report["ratios"]) == {"0.877", "1.2"}
    for ratio in report["ratios"].values():
        assert ratio["same_bits"] is True
        assert ratio["impacts_per_period"] > 0.0  # the searches find events: they are what is measured
        assert all(ns > 0.0 for ns in ratio["ns_per_start_period"].values())
