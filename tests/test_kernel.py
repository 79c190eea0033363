"""The compiled kernel: the source it is compiled from, run as Python, gives its bits; the GPU's
flat loop gives the CPU's nested loops' bits; the Lyapunov measure marches the pair that the
kernel's own period-by-period march gives; its switch rules are the model's; the GPU's code is the
same source, run here on numba's CUDA simulator. Where its compiled code is kept:
``test_kernel_cache.py``.

The agreement with the scalar core and with the FMU (the independent checks of its physics), one
trajectory alone against a batch of 10,000, and grazing contacts are in ``test_batch.py``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from piezo_fmu import Parameters
from piezo_fmu.model import dynamics
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, device_error
from piezo_fmu.solver.batch import kernel
from piezo_fmu.solver.batch.kernel import flat, layout, location, periods, rounds, switches
from piezo_fmu.solver.batch.model import BatchModel

ROOT = Path(__file__).resolve().parents[1]
W_N = math.sqrt(1000.0)
DAMPERS = {
    "nominal": Parameters(voltage_model=1, R_load=3.59e6),
    "coupled circuit": Parameters(voltage_model=2, R_load=3.59e6),
    "stiff contact": Parameters(barrier_mode=1, voltage_model=0),
}


def random_starts(params, count, seed=0):
    """Starts as ``fractions`` draws them: the main mass anywhere within a gap, the impact mass at
    rest anywhere in the gap."""
    rng = np.random.default_rng(seed)
    d = params.d
    p = rng.uniform(-d, d, count)
    return np.column_stack([p, rng.uniform(-d * W_N, d * W_N, count), p + rng.uniform(-d / 2, d / 2, count),
                            np.zeros(count)])


def scaled_gap(a, b, omega):
    return np.nanmax(np.abs((a - b) * np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])))


def march_as_python(march_one, tables, starts, periods_, failed=None):
    """The outputs, final states and failures of ``march_one`` (the source, uncompiled) over every
    start."""
    n = len(starts)
    state = np.zeros((7, n))
    state[:4] = starts.T
    failed = np.zeros(n, bool) if failed is None else failed.copy()
    out = (np.empty((periods_, n, 4)), np.empty((periods_, n)), np.empty((periods_, n), np.int64),
           np.empty((periods_, n)), np.empty((periods_, n)))
    for i in range(n):
        march_one(True, i, state, failed, np.zeros(n, np.int64), *tables.arguments(), *out, np.empty(layout.WORK))
    return out, state, failed


@pytest.mark.parametrize("case", DAMPERS)
def test_the_source_run_as_python_gives_the_compiled_kernels_bits(case):
    """The scalar functions, uncompiled, march as the compiled kernel does, bit for bit: the
    compiled code is the source, with nothing rearranged (no fast-math)."""
    params = DAMPERS[case]
    drive = HarmonicHold(1.25 * W_N, 1e-3)
    starts = random_starts(params, 6)
    compiled = Ensemble(params, drive, starts).advance(2, observe=True)
    tables = kernel.Tables(BatchModel.of(params), [drive])
    out, _, _ = march_as_python(periods.march_one, tables, starts, 2)
    assert compiled["impacts"].sum() > 0
    for name, values in zip(("sections", "sides", "impacts", "top", "bottom"), out):
        assert np.array_equal(compiled[name], values), name


def march_both(run, n, periods_, failed):
    """The outputs, final states and failures of ``run(flat, state, failed, outputs)`` for the
    nested march and the flat one, from the same ``(7, n)`` states."""
    results = []
    for is_flat in (False, True):
        out = (np.empty((periods_, n, 4)), np.empty((periods_, n)), np.empty((periods_, n), np.int64),
               np.empty((periods_, n)), np.empty((periods_, n)))
        bad = failed.copy()
        state = run(is_flat, bad, out)
        results.append((out, state, bad))
    return results


def assert_same_bits(nested, flat_):
    for a, b in zip(nested[0] + (nested[1], nested[2]), flat_[0] + (flat_[1], flat_[2])):
        assert np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("case", DAMPERS)
@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_the_gpus_flat_march_gives_the_nested_marchs_bits(case, ratio):
    """The flat loop the GPU runs (:mod:`~piezo_fmu.solver.batch.kernel.flat`) and the nested loops
    the CPU runs, both compiled for the CPU: every output, the final states and the failures bit for
    bit, from random starts (most impacting; some failed before the march) and starts at a barrier."""
    params = DAMPERS[case]
    drive = HarmonicHold(ratio * W_N, 1e-3)
    tables = kernel.Tables(BatchModel.of(params), [drive])
    starts = random_starts(params, 1500, seed=4)
    # and starts at a barrier, within rounding of it (the searches' held first step and the onsets
    # due at once), moving in, out and along
    rng = np.random.default_rng(6)
    at = starts[:300].copy()
    at[:, 2] = at[:, 0] + np.sign(rng.uniform(-1, 1, 300)) * params.d / 2 * (1 + rng.integers(-20, 21, 300) * 1e-14)
    at[:, 3] = at[:, 1] + rng.choice([-1e-3, 0.0, 1e-3], 300)
    starts = np.concatenate([starts, at])
    failed = np.zeros(len(starts), bool)
    failed[::300] = True

    def run(is_flat, bad, out):
        state = np.zeros((7, len(starts)))
        state[:4] = starts.T
        got = kernel.march("cpu", tables, state, bad, np.zeros(len(starts), np.int64), 6, True, flat=is_flat)
        for k, name in enumerate(("sections", "sides", "impacts", "top", "bottom")):
            out[k][...] = got[name]
        return state

    nested, flat_ = march_both(run, len(starts), 6, failed)
    assert nested[0][2].sum() > 3 * len(starts)
    assert_same_bits(nested, flat_)


@pytest.mark.parametrize("cap", [{"MAX_ITERATIONS": 5}, {"MAX_ROUNDS": 1}])
def test_the_flat_march_fails_where_the_nested_one_does(cap, monkeypatch):
    """With the event search or the rounds of a step capped low (the source run as Python), every
    start fails in its first period, after at least one onset: both loops fail at the same instant
    and leave the same NaNs, voltages and onset counts."""
    for name, value in cap.items():
        for module in (location, rounds, flat):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, value)
    params = DAMPERS["coupled circuit"]
    drive = HarmonicHold(1.25 * W_N, 1e-3)
    tables = kernel.Tables(BatchModel.of(params), [drive])
    starts = random_starts(params, 8, seed=5)
    nested, flat_ = (march_as_python(march_one, tables, starts, 2) for march_one in (periods.march_one,
                                                                                     flat.march_one_flat))
    (sections, _, impacts, _, _), _, failed = nested
    assert failed.all() and np.isnan(sections).all()
    assert (impacts[0] >= 1).all() and (impacts[1] == 0).all()
    assert_same_bits(nested, flat_)


def test_the_lyapunov_measure_marches_the_pair_the_kernel_marches_period_by_period():
    """``Ensemble.separate`` (the pair in one pass of the kernel, :func:`.periods.separate_one`)
    against the trajectory and its companion marched as two ordinary trajectories of an ensemble,
    one period at a time, the companion put back along the separation after every period by
    numpy: the same log stretches to rounding, the same trajectory bit for bit."""
    params = DAMPERS["nominal"]
    drive = HarmonicHold(1.25 * W_N, 1e-3)
    starts = random_starts(params, 5, seed=2)
    scale = np.tile([1.0, 1.0 / drive.omega, 1.0, 1.0 / drive.omega], (5, 1))
    delta = 1e-8 * np.abs(starts * scale).max(axis=1)
    direction = np.array([0.5, -0.5, 0.5, 0.5])
    offset = direction[None] * delta[:, None] / scale
    count = 6
    fast = Ensemble(params, drive, starts).separate(offset, scale, delta, count)
    pair = Ensemble(params, drive, np.concatenate([starts, starts]))
    companions = np.arange(10) >= 5
    logs = []
    for _ in range(count):
        states, sides = pair.states[:5], pair.sides[:5]
        pair.assign(companions, states + offset, sides)
        pair.advance(1)
        now = pair.states
        gap = np.linalg.norm((now[5:] - now[:5]) * scale, axis=1)
        logs.append(np.log(gap / delta))
        offset = (now[5:] - now[:5]) * (delta / gap)[:, None]
    assert np.isfinite(fast["logs"]).all() and fast["impacts"].sum() > 0
    # the same arithmetic but for the norm's sums (numpy's may add in another order): 0.0 here
    assert np.max(np.abs(fast["logs"] - np.array(logs))) < 1e-12
    assert np.array_equal(fast["samples"][-1], pair.states[:5, 0])


def thresholds(rng, count) -> list:
    """Random values, and values on both sides of zero down to the smallest doubles, and zero."""
    scale = 10.0 ** rng.uniform(-12, 4, count)
    tiny = rng.choice([-1, 1], 40) * 10.0 ** rng.uniform(-320, -300, 40)
    return (rng.standard_normal(count) * scale).tolist() + [0.0, -0.0, 5e-324, -5e-324, 2.2e-308] + tiny.tolist()


def test_the_kernels_switch_rules_are_the_models_on_both_sides_of_every_threshold():
    """:mod:`.kernel.switches` against :mod:`piezo_fmu.model.dynamics`, on random masses and
    velocities and on states straddling the threshold of ``approach_sign`` (the main spring and
    damper pushing neither way: ``K u + C u'`` near 0, either side, and exactly 0): the same
    velocities and losses after a capture and a release, bit for bit, and the same side."""
    rng = np.random.default_rng(11)
    for _ in range(2000):
        m, M_eq, M1 = (10.0 ** rng.uniform(-4, 2, 3)).tolist()
        M = M1 + M_eq
        dp, dq = (rng.standard_normal(2) * 10.0 ** rng.uniform(-9, 1, 2)).tolist()
        dq = dp if rng.uniform() < 0.05 else dq  # no relative velocity
        assert switches.capture(m, M_eq, dp, dq) == dynamics.capture(m, M_eq, dp, dq)
        assert switches.release(M, M1, M_eq, dp, dq) == dynamics.release(M, M1, M_eq, dp, dq)
    K, C = 1000.0, 0.1
    for u in thresholds(rng, 300):
        # u' chosen so that K u + C u' falls either side of 0, by a few ulp, or on it
        for du in (-K * u / C, math.nextafter(-K * u / C, math.inf), math.nextafter(-K * u / C, -math.inf),
                   float(rng.standard_normal())):
            for side in (1, -1):
                assert switches.approach_sign(K, C, u, du, float(side)) == dynamics.approach_sign(K, C, u, du, side)
    assert switches.approach_sign(K, C, math.nan, 0.0, 1.0) == dynamics.approach_sign(K, C, math.nan, 0.0, 1) == 0


def test_every_function_the_kernel_compiles_is_registered_where_it_is_defined():
    """The kernel's wiring is explicit: each function a registered function calls is itself
    registered (compiled for the target), found by what its code names, and no function is
    registered twice under one name in a module."""
    from piezo_fmu.solver.batch.attractors import books
    from piezo_fmu.solver.batch.kernel import cpu, flows, inputs, ledger, registry, scalars

    modules = (books, cpu, flat, flows, inputs, ledger, location, periods, rounds, scalars, switches)
    registered = {f for f in registry._KINDS if f.__module__ in {m.__name__ for m in modules}}
    assert len(registered) >= 30
    for function in registered:
        for name in function.__code__.co_names:
            value = function.__globals__.get(name)
            if callable(value) and getattr(value, "__module__", "").startswith("piezo_fmu.solver.batch"):
                assert value in registry._KINDS, f"{function.__qualname__} calls {name}, which is not registered"


def on_the_simulator(script: Path, starts: np.ndarray) -> list[str]:
    """The lines ``script`` prints, run on numba's CUDA simulator with ``starts`` (JSON) as its
    argument; it must succeed."""
    result = subprocess.run([sys.executable, str(script), json.dumps(starts.tolist())], capture_output=True, text=True,
                            env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"), timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    return result.stdout.splitlines()


def test_the_gpu_code_is_the_same_source_run_on_numbas_cuda_simulator(tmp_path):
    """The GPU path (numba's CUDA target: one thread a trajectory, one launch a block of periods)
    compiled from the same source, run on numba's CUDA simulator (CI has no GPU): the motion of
    the CPU kernel."""
    script = tmp_path / "gpu.py"
    script.write_text(
        "import json, math, sys\n"
        "import numpy as np\n"
        "from piezo_fmu import Parameters\n"
        "from piezo_fmu.solver.batch import Ensemble, HarmonicHold\n"
        "params = Parameters(voltage_model=2, R_load=3.59e6)\n"
        "drive = HarmonicHold(1.25 * math.sqrt(1000.0), 1e-3)\n"
        "starts = np.array(json.loads(sys.argv[1]))\n"
        "runs = [Ensemble(params, drive, starts, device=d).advance(2, observe=True) for d in ('gpu', 'cpu')]\n"
        "from piezo_fmu.solver.batch import kernel\n"
        "e = Ensemble(params, drive, starts, device='gpu')\n"
        "quiet = kernel.march('gpu', e._tables, e._state, e.failed, e.group, 2, observe=False)\n"
        "print(json.dumps({'extremes': [bool(np.isnan(quiet[k]).all()) for k in ('top', 'bottom')],\n"
        "                  'writeable': quiet['top'].flags.writeable,\n"
        "                  'gap': float(np.abs(quiet['sections'] - runs[0]['sections']).max())}))\n"
        "print(json.dumps({k: [runs[0][k].tolist(), runs[1][k].tolist()] for k in runs[0]}))\n")
    lines = on_the_simulator(script, random_starts(DAMPERS["coupled circuit"], 3, seed=3))
    runs = json.loads(lines[-1])
    gpu, cpu = ({k: np.array(v[j]) for k, v in runs.items()} for j in (0, 1))
    assert cpu["impacts"].sum() > 0
    assert np.array_equal(gpu["impacts"], cpu["impacts"])
    assert np.array_equal(gpu["sides"], cpu["sides"])
    assert scaled_gap(gpu["sections"], cpu["sections"], 1.25 * W_N) < 1e-12
    # unobserved, the GPU's extremes (NaN) are not copied back: a read-only NaN view; the motion is the same
    quiet = json.loads(lines[-2])
    assert quiet == {"extremes": [True, True], "writeable": False, "gap": 0.0}


def test_a_study_on_the_gpu_marches_its_starts_there_and_newtons_small_ensembles_on_the_cpu(tmp_path):
    """``settle`` on the GPU (numba's CUDA simulator here): the starts march on the GPU, the orbit
    finder's ensembles (Newton's seeds and neighbours, a few trajectories each, thousands of launches
    that cost milliseconds each on a GPU) on the CPU; the verdicts are the CPU's."""
    script = tmp_path / "settle.py"
    script.write_text(
        "import json, math, sys\n"
        "import numpy as np\n"
        "from piezo_fmu import Parameters\n"
        "from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, kernel, settle\n"
        "launches = []\n"
        "launch = kernel._launch\n"
        "def spy(device, entry, args, n, *rest, **named):\n"
        "    launches.append([device, entry.__name__, n])\n"
        "    return launch(device, entry, args, n, *rest, **named)\n"
        "kernel._launch = spy\n"
        "params = Parameters(voltage_model=1, R_load=3.59e6)\n"
        "drive = HarmonicHold(1.2 * math.sqrt(1000.0), 1e-3)\n"
        "starts = np.array(json.loads(sys.argv[1]))\n"
        "runs = {}\n"
        "for device in ('gpu', 'cpu'):\n"
        "    done = settle(params, drive, starts, settings=SettleSettings(max_cycles=200), device=device)\n"
        "    runs[device] = {'labels': done.labels.tolist(), 'periods': done.periods.tolist(),\n"
        "                    'final': done.final.tolist(), 'attractors': len(done.attractors),\n"
        "                    'launches': launches[:]}\n"
        "    launches.clear()\n"
        "print(json.dumps(runs))\n")
    runs = json.loads(on_the_simulator(script, random_starts(DAMPERS["nominal"], 4, seed=5))[-1])
    gpu, cpu = runs["gpu"], runs["cpu"]
    marches = [n for device, name, n in gpu["launches"] if device == "gpu"]
    assert marches and marches[0] == 4  # the starts, on the GPU
    newtons = [n for device, name, n in gpu["launches"] if device == "cpu"]
    assert newtons, "the orbit finder marched nothing on the CPU"
    assert all(device == "cpu" for device, name, n in cpu["launches"])
    assert gpu["labels"] == cpu["labels"] and min(cpu["labels"]) >= 0  # every start reached an orbit
    assert gpu["periods"] == cpu["periods"] and gpu["attractors"] == cpu["attractors"]
    assert np.max(np.abs(np.array(gpu["final"]) - np.array(cpu["final"]))) < 1e-12


def test_the_gpu_benchmark_runs_on_the_simulator_with_the_packages_a_gpu_machine_has(tmp_path):
    """``benchmarks/bench_gpu.py`` (the one call a session lent a GPU makes) on numba's CUDA
    simulator, tiny sizes, run from the source tree (``PYTHONPATH=src``): it reports each throughput
    row and finds the GPU path's sections equal to the CPU's."""
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_gpu.py"), "--sizes", "3,5",
                             "--periods", "2", "--agree", "4", "--agree-periods", "2", "--registers", "0,64",
                             "--orderings", "1", "--march", "4", "--march-block", "2",
                             "--settle", "4", "--settle-cpu", "4", "--settle-budget", "400", "--settle-ratio", "1.2"],
                            capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout)
    assert report["simulator"] is True
    assert [row["starts"] for row in report["throughput"]] == [3, 5]
    for row in report["throughput"]:
        for name in ("gpu_with_transfers", "gpu_resident", "cpu_every_core"):
            assert row[name]["start_periods_per_s"] > 0.0, name
    agreement = report["agreement"]
    assert agreement["impacting"] > 0
    assert agreement["same_onsets_every_period"] == agreement["starts"] == 4
    assert agreement["max_difference_all_m"] <= 1e-12
    assert report["target"]["met"] is False  # 5 starts are not a million
    caps = report["register_caps"]
    assert [row["registers_cap"] for row in caps] == [None, 64]
    assert all(row["same_bits_as_first"] and row["start_periods_per_s"] > 0.0 for row in caps)
    # sorted, the trajectories march as in their own order, bit for bit
    (ordering,) = report["orderings"]
    assert sum(ordering["impacts_last_period"].values()) == 5 and ordering["moved_by_impacts_side_p"] > 0
    for key in ("as_started", "impacts", "impacts_side_p", "p"):
        assert ordering[key]["same_bits_as_started"] and ordering[key]["start_periods_per_s"] > 0.0, key
    plain, ordered = report["long_march"]
    assert (plain["sorted"], ordered["sorted"]) == (False, True)
    assert plain["periods"] == ordered["periods"] == 4 and len(ordered["millions_a_second_each_block"]) == 2
    assert ordered["same_bits_as_unsorted"] is True and ordered["moved"] > 0
    settled = report["settle"]
    assert (settled["gpu"]["starts"], settled["cpu"]["starts"], settled["compared"]) == (4, 4, 4)
    assert settled["gpu"]["undecided"] == settled["cpu"]["undecided"] == 0
    assert settled["same_destination"] == 4  # the simulator's motion is the CPU's
    assert settled["gpu"]["start_periods"] > 0 and settled["cpu"]["start_periods_per_s"] > 0.0


def test_a_numba_cuda_that_cannot_compile_with_this_numpy_is_named_before_any_march():
    """numba-cuda 0.30.4 compiles nothing with numpy 2.5 (``np.row_stack`` is gone; seen on a lent
    H200): the GPU device says which packages and why, instead of a traceback at the first march."""
    code = ("from piezo_fmu.solver.batch import device_error\n"
            "import numpy\n"
            "del numpy.row_stack  # as numpy 2.5 has it\n"
            "print(device_error('gpu'))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                            env=dict(os.environ, PYTHONPATH=str(ROOT / "src")))
    assert result.returncode == 0, result.stderr[-3000:]
    message = result.stdout.strip()
    assert message.startswith("device = 'gpu': numba-cuda ") and "cannot compile with numpy" in message
    assert "row_stack" in message and "allowed devices here: 'cpu'" in message


def test_without_a_gpu_the_gpu_device_says_what_is_missing():
    error = device_error("gpu")
    assert error is not None and error.startswith("device = 'gpu': ") and "allowed devices here: 'cpu'" in error
    with pytest.raises(ValueError, match="device = 'gpu': .*allowed devices here: 'cpu'"):
        Ensemble(DAMPERS["nominal"], HarmonicHold(W_N, 1e-3), [(0.0, 0.0, 0.0, 0.0)], device="gpu")
    with pytest.raises(ValueError, match=r"device = 'tpu' is not known; allowed values \('cpu', 'gpu'\)"):
        Ensemble(DAMPERS["nominal"], HarmonicHold(W_N, 1e-3), [(0.0, 0.0, 0.0, 0.0)], device="tpu")
