"""The batch engine under a base input of its own (:mod:`piezo_fmu.solver.batch.input_ensemble`): the
march a study of random base excitation makes. Each trajectory follows the scalar core driven by the
same first-order hold (the independent check: the core integrates by Taylor brackets, the kernel in
closed form), its energy ledger closes and agrees with the core's, and its bits depend neither on
how its input is cut into blocks nor on the trajectories beside it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from piezo_fmu import Parameters, Simulator
from piezo_fmu.solver.batch.input_ensemble import LEDGER, InputEnsemble
from piezo_fmu.solver.batch.kernel import input_hold, layout
from piezo_fmu.solver.batch.model import BatchModel

START = dict(p0=0.0, q0=0.0, dp0=0.0, dq0=0.0)
DAMPERS = {
    "coupled circuit": Parameters(voltage_model=2, R_load=3.59e6, **START),
    "quasi-static": Parameters(voltage_model=0, **START),
    "stiff contact, undamped main mass": Parameters(barrier_mode=1, voltage_model=2, C=0.0, R_load=1e5, **START),
    "heavy impact mass, damped": Parameters(voltage_model=2, m=0.3, C=20.0, R_load=3.59e6, **START),
}


def random_input(count: int, steps: int, h: float, level: float, seed: int = 1) -> tuple:
    """Base inputs as an FMU takes them: nodes (count, steps + 1) from rest and slopes (count, steps), the
    displacement of a random acceleration of about ``level`` m/s^2."""
    rng = np.random.default_rng(seed)
    velocity = np.cumsum(rng.standard_normal((count, steps)) * level * h, axis=1)
    velocity -= velocity.mean(axis=1, keepdims=True)
    nodes = np.hstack([np.zeros((count, 1)), np.cumsum(velocity * h, axis=1)])
    return nodes, np.diff(nodes, axis=1) / h


def core_run(params, nodes, slopes, h):
    """The scalar core under the same hold: ``p`` and the impacts so far at each step's end, and its
    ledger's flows in the order of :data:`LEDGER`."""
    sim = Simulator(params, y0=nodes[0], v0=slopes[0])
    positions, impacts = [], []
    for k in range(len(slopes)):
        sim.advance((k + 1) * h, nodes[k], slopes[k])
        positions.append(sim.state.p)
        impacts.append(sim.metrics.impact_count)
    e = sim.energy
    return np.array(positions), np.array(impacts), np.array(
        [e.work_base, e.dissipated_C, e.dissipated_Ceq, e.plastic, e.harvested_left, e.harvested_right])


@pytest.mark.parametrize("case", DAMPERS)
def test_under_its_own_input_each_trajectory_follows_the_core_and_its_ledger(case):
    """Six random inputs, 2 s at h = 2 ms, some 20 to 50 impacts each: the core's contact onsets in
    every step, ``p`` at every step within 1e-9 m, and every flow of the ledger within 1e-8 of the
    base's work (the two codes' trajectories part by some 1e-11 m over the impacts, the flows with
    them)."""
    params, h = DAMPERS[case], 2e-3
    nodes, slopes = random_input(6, 1000, h, 5.0)
    ensemble = InputEnsemble(params, h, np.zeros((6, 4)))
    positions, onsets = ensemble.advance(nodes, slopes, onsets=True)
    assert ensemble.counts.min() >= 5 and np.array_equal(onsets.sum(axis=1), ensemble.counts)
    for i in range(6):
        core_p, core_impacts, core_flows = core_run(params, nodes[i], slopes[i], h)
        assert np.array_equal(np.cumsum(onsets[i]), core_impacts)
        assert np.abs(positions[i] - core_p).max() < 1e-9
        assert np.abs(ensemble.ledger[i] - core_flows).max() < 1e-8 * core_flows[0]
    if params.voltage_model != 2:
        assert (ensemble.ledger[:, LEDGER.index("harvested_left"):] == 0.0).all()  # no circuit in the kernel


@pytest.mark.parametrize("case", DAMPERS)
def test_the_energy_ledger_closes_for_every_trajectory(case):
    """The base's work equals the energy stored now (from rest) plus the dissipated, plastic and
    harvested energy, for 200 trajectories of 8 s, the accounts restarted halfway (a warm-up) and
    closing again: within 1e-11 of the largest work, the rounding of 4,000 steps and thousands of
    impacts whose modal sums cancel (2.2e-12 at most, the stiff contact's; 2e-13 for the others)."""
    params, h = DAMPERS[case], 2e-3
    nodes, slopes = random_input(200, 4000, h, 3.0, seed=2)
    ensemble = InputEnsemble(params, h, np.zeros((200, 4)))
    ensemble.advance(nodes[:, :2001], slopes[:, :2000])
    stored = ensemble.energy(nodes[:, 2000])
    balance = ensemble.ledger[:, 0] - stored - ensemble.ledger[:, 1:].sum(axis=1)
    assert np.abs(balance).max() < 1e-11 * ensemble.ledger[:, 0].max()
    ensemble.restart_accounts()
    ensemble.advance(nodes[:, 2000:], slopes[:, 2000:])
    balance = ensemble.ledger[:, 0] - (ensemble.energy(nodes[:, -1]) - stored) - ensemble.ledger[:, 1:].sum(axis=1)
    assert ensemble.counts.sum() > 1000 and not ensemble.failed.any()
    assert np.abs(balance).max() < 1e-11 * np.abs(ensemble.ledger[:, 0]).max()


def test_a_trajectorys_bits_do_not_depend_on_the_cut_of_its_input_or_on_its_batch():
    """The same inputs in one block, in blocks of 1, 299, 1 and 700 steps, and one trajectory alone:
    the positions, the final states, the accounts, bit for bit."""
    params, h = DAMPERS["coupled circuit"], 2e-3
    nodes, slopes = random_input(40, 1000, h, 5.0, seed=3)
    whole = InputEnsemble(params, h, np.zeros((40, 4)))
    positions = whole.advance(nodes, slopes)
    cut = InputEnsemble(params, h, np.zeros((40, 4)))
    pieces = [cut.advance(nodes[:, a:b + 1], slopes[:, a:b]) for a, b in ((0, 1), (1, 300), (300, 301), (301, 1000))]
    alone = InputEnsemble(params, h, np.zeros((1, 4)))
    single = alone.advance(nodes[17:18], slopes[17:18])
    assert whole.counts.sum() > 500
    assert np.array_equal(np.hstack(pieces), positions) and np.array_equal(single[0], positions[17])
    for name in ("states", "sides", "voltages", "stats", "counts", "ledger"):
        assert np.array_equal(getattr(cut, name), getattr(whole, name)), name
        assert np.array_equal(getattr(alone, name)[..., 0] if name == "voltages" else getattr(alone, name)[0],
                              getattr(whole, name)[..., 17] if name == "voltages" else getattr(whole, name)[17]), name


@pytest.mark.parametrize("C", [0.1, 63.24555320336759, 200.0])
def test_a_hold_steps_free_flight_integrals_are_the_closed_forms_integrated_by_quad(C):
    """The constants a free hold step's flows use (``input_hold``: the 8-point Gauss-Legendre rule on
    pieces of the step) against ``scipy.integrate.quad`` of the same closed forms, underdamped,
    critically damped (``C = 2 sqrt(K M)``) and overdamped, to 1e-13; and a patch's decaying energy
    into its load where the circuit acts back (voltage model 2), none where the engine carries no
    voltage (voltage model 1: ``R C_p`` is then no decay time of the engine's)."""
    assert input_hold(BatchModel.of(Parameters(C=C, voltage_model=1)), 0.01)[layout.H_LOAD] == 0.0
    model = BatchModel.of(Parameters(C=C, voltage_model=2))
    h = 0.01
    hold = input_hold(model, h)

    def c(t):
        return float(model.free.coefficients(np.array(t))[0])

    def s(t):
        return float(model.free.coefficients(np.array(t))[1])

    expected = {layout.H_C: c, layout.H_S: s, layout.H_CC: lambda t: c(t) ** 2, layout.H_CS: lambda t: c(t) * s(t),
                layout.H_SS: lambda t: s(t) ** 2}
    for offset, integrand in expected.items():
        value = quad(integrand, 0.0, h, epsabs=0.0, epsrel=1e-13)[0]
        assert hold[offset] == pytest.approx(value, rel=1e-13, abs=1e-30), offset
    assert hold[layout.H_LOAD] == pytest.approx(quad(lambda t: math.exp(-2 * t / model.tau_e), 0, h)[0]
                                                / model.params.R_load, rel=1e-13)


def test_bad_input_is_refused_with_what_is_allowed():
    params = DAMPERS["coupled circuit"]
    with pytest.raises(ValueError, match=r"step = 0.0 s is out of range; allowed range \(0, inf\)"):
        InputEnsemble(params, 0.0, np.zeros((2, 4)))
    ensemble = InputEnsemble(params, 1e-3, np.zeros((2, 4)))
    with pytest.raises(ValueError, match=r"nodes \(2, 5\) and slopes \(2, 5\): allowed shapes \(2, B \+ 1\)"):
        ensemble.advance(np.zeros((2, 5)), np.zeros((2, 5)))
    with pytest.raises(ValueError, match=r"states\[1\] .*allowed range"):
        InputEnsemble(params, 1e-3, [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)])


def test_the_gpu_marches_an_input_as_the_cpu_does(tmp_path):
    """The input march compiled for numba's CUDA target, run on its simulator (CI has no GPU): the CPU's
    positions, accounts and states."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "gpu.py"
    script.write_text(
        "import json, sys\n"
        "import numpy as np\n"
        "from piezo_fmu import Parameters\n"
        "from piezo_fmu.solver.batch.input_ensemble import InputEnsemble\n"
        "nodes, slopes = (np.array(a) for a in json.loads(sys.argv[1]))\n"
        "params = Parameters(voltage_model=2, R_load=3.59e6)\n"
        "runs = []\n"
        "for device in ('gpu', 'cpu'):\n"
        "    e = InputEnsemble(params, 2e-3, np.zeros((3, 4)), device=device)\n"
        "    positions = e.advance(nodes, slopes)\n"
        "    runs.append([positions.tolist(), e.states.tolist(), e.ledger.tolist(), e.counts.tolist()])\n"
        "print(json.dumps(runs))\n")
    nodes, slopes = random_input(3, 150, 2e-3, 5.0, seed=4)
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, str(script), json.dumps([nodes.tolist(), slopes.tolist()])],
                          capture_output=True, text=True, timeout=900,
                          env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(root / "src")))
    assert done.returncode == 0, done.stderr[-3000:]
    gpu, cpu = json.loads(done.stdout.splitlines()[-1])
    assert sum(cpu[3]) > 0  # impacts happened
    for a, b in zip(gpu, cpu):
        assert np.abs(np.array(a) - np.array(b)).max() <= 1e-12 * max(1.0, np.abs(np.array(b)).max())
