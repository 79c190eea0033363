"""``benchmarks/bench_diagram.py``: where the bifurcation diagram's time goes. Its figures
rest on three facts, checked here on a small diagram: the timed run is the diagram itself (the
same points as the diagram without the timers), every launch of the kernel is counted once and
owned by the piece that made it (the main loop's one a block, the rest in Newton and the checks),
and each piece's own time is what is left of it once its kernel launches and the pieces it calls
are taken out (never negative)."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "bench_diagram.py"
SMALL = ("--count", "6", "--max-cycles", "200")


def bench(tmp_path, *arguments, env=None):
    return subprocess.run([sys.executable, str(SCRIPT), *arguments], capture_output=True, text=True, timeout=600,
                          cwd=tmp_path, env={**os.environ, **(env or {})})


def points(folder: Path) -> list:
    """The diagram's points without their CPU seconds (the one field a clock writes)."""
    sweeps = json.loads((folder / "points.json").read_text())["sweeps"]
    return [[{k: v for k, v in p.items() if k != "cpu_seconds"} for p in s["points"]] for s in sweeps]


def test_the_diagram_benchmark_times_the_diagram_itself_and_owns_each_launch_once(tmp_path):
    env = {"NUMBA_NUM_THREADS": "1"}
    timed = bench(tmp_path, *SMALL, "--out", str(tmp_path / "timed"), env=env)
    assert timed.returncode == 0, timed.stderr[-3000:]
    bare = bench(tmp_path, *SMALL, "--out", str(tmp_path / "bare"), "--bare", env=env)
    assert bare.returncode == 0, bare.stderr[-3000:]
    report, plain = json.loads(timed.stdout), json.loads(bare.stdout)
    assert set(plain) == {"sweeps_s", "start_periods"}
    assert points(tmp_path / "timed") == points(tmp_path / "bare")
    assert report["start_periods"] == plain["start_periods"]
    calls = report["calls"]
    # the main loop launches the kernel once a block and extends its history once a block
    assert calls["kernel"] == calls["_extend"] == calls["_find_orbits"] > 0
    assert calls["newton"] > 0 and calls["verify"] > 0 and calls["measure"] > 0
    owners = report["kernel_by_owner_s"]
    assert {"kernel", "kernel in newton", "kernel in verify", "kernel in measure"} <= set(owners)
    assert abs(sum(owners.values()) - report["kernel_s"]) <= 1e-9
    assert 0.0 < report["kernel_s"] < report["sweeps_s"]
    assert abs(report["kernel_s"] + report["rest_s"] - report["sweeps_s"]) <= 1e-9
    assert all(seconds >= 0.0 for seconds in report["pieces"].values()), report["pieces"]
    assert report["floor_2_cores_s"] == report["kernel_s"] / 2.0


def test_the_diagram_benchmark_refuses_bad_options_naming_them(tmp_path):
    count = bench(tmp_path, "--count", "0")
    assert count.returncode == 2 and "--count 0" in count.stderr and "allowed range [2, inf)" in count.stderr
    fmu = bench(tmp_path, "--count", "4", "--fmu", "missing.fmu")
    assert fmu.returncode == 2 and "FMU not found at missing.fmu" in fmu.stderr
    threads = bench(tmp_path, "--count", "4", env={"NUMBA_NUM_THREADS": "2"})
    assert threads.returncode == 2 and "NUMBA_NUM_THREADS = '2'" in threads.stderr
    assert "allowed: unset or '1'" in threads.stderr
