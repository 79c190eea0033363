"""The simulation core against closed forms, conservation laws and its own contracts."""

import json
import math

import numpy as np
import pytest

from piezo_fmu import EXPLICIT, Parameters, Simulator, derive_barrier
from piezo_fmu.solver.propagation import LinearPhase
from scipy.linalg import expm


def harmonic_run(params, t_end=2.0, Y=2e-3, omega=31.0, hold=1e-3):
    """Base ``Y sin(omega t)`` fed as a first-order hold every ``hold`` seconds."""
    sim = Simulator(params)
    for k in range(int(round(t_end / hold))):
        t = k * hold
        sim.advance((k + 1) * hold, Y * math.sin(omega * t), Y * omega * math.cos(omega * t))
    return sim


def three_sig(x):
    return f"{x:.3g}"


def test_barrier_derivation_matches_model_to_three_digits():
    b = derive_barrier(Parameters())
    assert three_sig(b.M_eq) == three_sig(3.93e-3)
    assert three_sig(b.K_eq) == three_sig(62.95e3)
    assert three_sig(b.k_V) == three_sig(6.83e6)
    assert b.eta1 == pytest.approx(0.25 * Parameters().L, rel=1e-12)
    assert b.beta1 * Parameters().L == pytest.approx(1.8751040687, rel=1e-10)
    assert b.kappa1 == pytest.approx(0.7340955, rel=1e-7)


def test_explicit_barrier_mode_passes_given_values_through():
    p = Parameters(barrier_mode=EXPLICIT, M_eq=0.0292, K_eq=46.7753e6)
    b = derive_barrier(p)
    assert (b.M_eq, b.K_eq, b.explicit) == (0.0292, 46.7753e6, True)
    assert b.k_V == derive_barrier(Parameters()).k_V  # the voltage gain stays geometric


def test_no_impacts_equals_analytic_damped_oscillator():
    p0, dp0, q0, dq0 = 0.01, 0.05, 0.002, 0.003
    params = Parameters(d=2.0, p0=p0, dp0=dp0, q0=q0, dq0=dq0)
    sim = Simulator(params)
    w0 = math.sqrt(params.K / params.M)
    zeta = params.C / (2 * math.sqrt(params.K * params.M))
    wd = w0 * math.sqrt(1 - zeta**2)
    a = zeta * w0
    worst = 0.0
    for t in np.linspace(0.0, 2.0, 201)[1:]:
        sim.advance(t, 0.0, 0.0)
        exact = math.exp(-a * t) * (p0 * math.cos(wd * t) + (dp0 + a * p0) / wd * math.sin(wd * t))
        exact_v = math.exp(-a * t) * (dp0 * math.cos(wd * t) - (a * dp0 + w0**2 * p0) / wd * math.sin(wd * t))
        s = sim.state
        worst = max(worst, abs(s.p - exact) / p0, abs(s.dp - exact_v) / (w0 * p0))
        assert s.q == pytest.approx(q0 + dq0 * t, rel=1e-14)
    assert sim.metrics.impact_count == 0
    assert worst <= 1e-12


def test_phase_flow_is_the_matrix_exponential():
    sim = Simulator(Parameters())
    for phase in (sim._free, sim._contact[1]):
        x = np.array([1e-3, -2e-3, 0.3, -0.1, 1.0])
        c = phase.coefficients(x, phase.h)
        exact = expm(phase.A * phase.h) @ x
        assert np.allclose(c.sum(axis=0), exact, rtol=1e-13, atol=1e-13 * np.abs(exact).max())


@pytest.mark.parametrize("M, K, C", [(2.0, 2e3, 3.0), (1.0, 1.0, 10.0), (1.0, 4.0, 4.0), (2.0, 0.0, 1.0),
                                     (1.0, 1e6, 0.0), (1.0, 1e3, 1e5)])
def test_free_flight_spectral_radius_in_closed_form_equals_the_eigenvalues(M, K, C):
    # Under-, critically and overdamped, and a free mass: the bracket length of free flight.
    from piezo_fmu.model.dynamics import free_matrix, free_spectral_radius

    eigen = np.max(np.abs(np.linalg.eigvals(free_matrix(M, K, C))))
    assert free_spectral_radius(M, K, C) == pytest.approx(eigen, rel=1e-12)


@pytest.mark.parametrize("model", [0, 2])
def test_left_barrier_is_the_right_one_mirrored_exactly(model):
    # The left barrier's phase and bracket maps are made from the right one's by sign changes:
    # they must equal, bit for bit, what a direct construction gives.
    from piezo_fmu.model.dynamics import LEFT, contact_matrix, event_functionals
    from piezo_fmu.model.energy import energy_rates
    from piezo_fmu.solver.brackets import BracketMaps

    params = Parameters(voltage_model=model)
    sim = Simulator(params)
    damper = sim.damper
    coupling = (sim.barrier.chi, sim.barrier.C_p, params.R_load) if model == 2 else None
    A = contact_matrix(damper.M_contact, damper.m_contact, params.K, params.C, sim.barrier.K_eq, params.C_eq, params.d,
                       LEFT, coupling)
    direct = LinearPhase(A)
    mirrored = sim._contact[LEFT]
    assert np.array_equal(mirrored.A, A) and mirrored.h == direct.h
    assert np.array_equal(damper.matrix(LEFT), A)
    assert np.array_equal(mirrored._terms, direct._terms)
    n = A.shape[0]
    maps = BracketMaps(direct, event_functionals(LEFT, params.d, n), energy_rates(LEFT, params.K, params.C, n))
    assert np.array_equal(sim._opener.maps[LEFT].stacked, maps.stacked)
    assert sim._opener.maps[LEFT].noise_rows == maps.noise_rows


def test_booked_ledger_equals_the_ledger_read_on_the_open_bracket():
    # Booked at a bracket's close by Hilbert quadratic forms, read on an open bracket from the
    # primitives: two evaluations of the same integrals, equal to rounding, in both phases.
    sim = Simulator(Parameters())
    checked = set()
    for k in range(1, 3001):
        t = (k - 1) * 1e-4  # a moving base, so that the base's work is not zero
        sim.advance(k * 1e-4, 1e-3 * math.sin(31.0 * t), 31e-3 * math.cos(31.0 * t))
        br = sim._bracket
        if br is None or br.s == 0.0:
            continue
        read, booked = sim._ledger.open_reading(br), sim._ledger.booked(br)
        for a, b in zip(read, booked):
            assert b == pytest.approx(a, rel=1e-12, abs=1e-16 * sim.energy.initial)
        assert read[0] > 0.0 and read[2] != 0.0
        checked.add(sim._side)
    assert checked == {0, 1, -1}


@pytest.mark.parametrize("f, lo, hi, root", [
    (math.cos, 1.0, 2.0, math.pi / 2),
    (lambda x: x**3 - 2.0, 0.0, 2.0, 2.0 ** (1.0 / 3.0)),
    (lambda x: (x - 0.3) ** 9, 0.0, 1.0, 0.3),  # flat: false position stalls, bisection goes on
    (lambda x: math.exp(x) - 1e10, 0.0, 40.0, math.log(1e10)),
    (lambda x: x - 1.0, 1.0, 5.0, 1.0),  # a root at an end
])
def test_bracketed_root_finder_reaches_the_last_bits(f, lo, hi, root):
    # The core's own bracketed solver (the runtime needs numpy only, not scipy's brentq).
    from piezo_fmu.model.scalar import bracketed

    assert abs(bracketed(f, lo, hi) - root) <= 8 * np.spacing(root)


def test_bracketed_root_finder_refuses_an_interval_without_a_sign_change():
    from piezo_fmu.model.scalar import bracketed

    with pytest.raises(ValueError, match="do not bracket a root"):
        bracketed(math.cos, 0.0, 1.0)


def test_one_contact_in_isolation_matches_eq7():
    # K, C of the main mass negligible (as eq. 5-6 assume): the relative motion is eq. 7.
    params = Parameters(K=1e-12, C=0.0, p0=0.0, q0=0.0039, dp0=0.0, dq0=0.5)
    b = derive_barrier(params)
    M1, m1 = params.M - b.M_eq, params.m + b.M_eq
    mu = m1 * M1 / (m1 + M1)
    a = params.C_eq / (2 * mu)
    wd = math.sqrt(b.K_eq / mu - a**2)
    t_on = (params.d / 2 - 0.0039) / 0.5
    v0 = 0.5 * params.m / m1  # relative velocity after the plastic capture of the tip mass

    def eq7(t):
        return v0 / wd * math.exp(-a * t) * math.sin(wd * t)

    sim = Simulator(params)
    sim.advance(t_on, 0.0, 0.0)  # exactly at onset: the contact is located, not yet entered
    worst = 0.0
    for tau in np.linspace(0.0, math.pi / wd, 40)[1:-1]:
        sim.advance(t_on + tau, 0.0, 0.0)
        worst = max(worst, abs(sim.deflection(+1) - eq7(tau)))
    sim.advance(t_on + 0.01, 0.0, 0.0)
    (impact,) = sim.impacts
    t_peak = math.atan2(wd, a) / wd
    assert impact.time == pytest.approx(t_on, rel=1e-12)
    assert impact.duration == pytest.approx(math.pi / wd, rel=1e-10)
    assert impact.max_deflection == pytest.approx(eq7(t_peak), rel=1e-10)
    assert worst <= 1e-10 * eq7(t_peak)


@pytest.mark.parametrize("case", ["nominal", "harmonic"])
def test_total_momentum_is_exact_across_every_switch(case):
    params = Parameters() if case == "nominal" else Parameters(p0=0.0, q0=0.0)
    sim = Simulator(params)
    if case == "nominal":
        sim.advance(2.0, 0.0, 0.0)
    else:
        sim = harmonic_run(params)
    M, m, M_eq = params.M, params.m, sim.barrier.M_eq
    assert len(sim.impacts) >= 20
    for i in sim.impacts:
        before = M * i.dp_before + m * i.dq_before
        after = (M - M_eq) * i.dp_after + (m + M_eq) * i.dq_after
        scale = M * abs(i.dp_before) + m * abs(i.dq_before)
        assert abs(after - before) <= 1e-14 * scale
        if not math.isnan(i.duration):
            before = (M - M_eq) * i.dp_sep_before + (m + M_eq) * i.dq_sep_before
            after = M * i.dp_sep_after + m * i.dq_sep_after
            scale = (M - M_eq) * abs(i.dp_sep_before) + (m + M_eq) * abs(i.dq_sep_before)
            assert abs(after - before) <= 1e-14 * scale


def test_energy_ledger_closes_over_nominal_run():
    sim = Simulator(Parameters())
    sim.advance(2.0, 0.0, 0.0)
    e = sim.energy
    assert sim.metrics.impact_count > 10
    assert e.dissipated_Ceq > 0 and e.plastic > 0 and e.dissipated_C > 0
    assert abs(e.balance_error) <= 1e-9 * e.initial


def test_energy_ledger_closes_under_harmonic_base_excitation():
    sim = harmonic_run(Parameters(p0=0.0, q0=0.0))
    e = sim.energy
    assert sim.metrics.impact_count > 10
    assert e.initial == 0.0 and e.work_base > 0
    assert abs(e.balance_error) <= 1e-9 * e.work_base


def test_energy_ledger_counts_work_of_base_displacement_jumps():
    # A zero-order hold: the host sets only the displacement, so the base jumps every step.
    sim = Simulator(Parameters(p0=0.0, q0=0.0))
    for k in range(1, 2001):
        sim.advance(k * 1e-3, 2e-3 * math.sin(31.0 * k * 1e-3), 0.0)
    e = sim.energy
    assert sim.metrics.impact_count > 5
    assert abs(e.balance_error) <= 1e-9 * e.work_base


def test_step_independence_one_call_and_20000_calls():
    one = Simulator(Parameters())
    one.advance(2.0, 0.0, 0.0)
    many = Simulator(Parameters())
    for k in range(1, 20001):
        many.advance(k * 1e-4, 0.0, 0.0)
    assert len(one.impacts) == len(many.impacts) > 10
    for a, b in zip(one.impacts, many.impacts):
        assert abs(a.time - b.time) <= 1e-12
        assert a.side == b.side
        assert a.voltage == pytest.approx(b.voltage, rel=1e-10)
    ma, mb = one.metrics.as_dict(), many.metrics.as_dict()
    for key in ma:
        assert mb[key] == pytest.approx(ma[key], rel=1e-10, nan_ok=True), key


def test_state_is_readable_and_snapshot_restores_bit_identically():
    sim = Simulator(Parameters())
    sim.advance(0.5, 0.0, 0.0)
    snap = json.loads(json.dumps(sim.snapshot()))
    sim.advance(1.0, 0.0, 0.0)
    again = Simulator.restore(Parameters(), snap)
    assert again.state.t == 0.5
    again.advance(1.0, 0.0, 0.0)
    assert again.snapshot() == sim.snapshot()
    assert again.state == sim.state


def test_grazing_double_crossing_inside_one_bracket_is_found():
    # p = A sin(w t) with no damping and the impactor at rest: r = -p reaches -A at w t = pi/2.
    # The left barrier sits 1e-8 A inside that excursion, so r crosses it twice within about
    # 2 sqrt(2e-8) / w = 9e-6 s, far inside one bracket (about 16 ms).
    A, K, M = 5e-3, 1000.0, 1.0
    w = math.sqrt(K / M)
    d = 2 * A * (1 - 1e-8)
    graze = Simulator(Parameters(C=0.0, d=d, p0=0.0, q0=0.0, dp0=A * w))
    assert graze.bracket_lengths["free"] > 1000 * 2 * math.sqrt(2e-8) / w
    graze.advance(0.1, 0.0, 0.0)
    assert graze.metrics.impact_count >= 1
    first = graze.impacts[0]
    assert first.side == -1
    assert first.time == pytest.approx(math.asin(d / (2 * A)) / w, abs=1e-12)

    miss = Simulator(Parameters(C=0.0, d=2 * A * (1 + 1e-8), p0=0.0, q0=0.0, dp0=A * w))
    miss.advance(0.1, 0.0, 0.0)
    assert miss.metrics.impact_count == 0


BAD = [
    ({"M": 0.0}, "M"), ({"M": -1.0}, "M"), ({"m": 0.0}, "m"), ({"m": -0.1}, "m"),
    ({"K": 0.0}, "K"), ({"K": -5.0}, "K"), ({"E_b": 0.0}, "E_b"), ({"E_p": -1.0}, "E_p"),
    ({"rho_b": 0.0}, "rho_b"), ({"rho_p": -1.0}, "rho_p"), ({"L": 0.0}, "L"), ({"t_b": -1e-3}, "t_b"),
    ({"W_b": 0.0}, "W_b"), ({"t_p": 0.0}, "t_p"), ({"W_p": 0.0}, "W_p"), ({"L_p": 0.0}, "L_p"),
    ({"g31": 0.0}, "g31"),
    ({"M": 0.003}, "M"),  # M <= M_eq
    ({"barrier_mode": EXPLICIT, "M": 0.02}, "M"),  # M <= printed M_eq
    ({"barrier_mode": EXPLICIT, "K_eq": 0.0}, "K_eq"), ({"barrier_mode": EXPLICIT, "M_eq": -1.0}, "M_eq"),
    ({"d": 0.0}, "d"), ({"d": -1e-3}, "d"),
    ({"x1": -1e-3}, "x1"), ({"x1": 0.075}, "x1"),
    ({"C": -0.1}, "C"), ({"C_eq": -1.0}, "C_eq"),
    ({"R_load": 0.0}, "R_load"), ({"R_load": -52e3}, "R_load"),
    ({"C": math.nan}, "C"), ({"K": math.inf}, "K"), ({"p0": -math.inf}, "p0"), ({"dq0": math.nan}, "dq0"),
    ({"q0": 0.015}, "q0"), ({"q0": 0.0059}, "q0"),
    ({"barrier_mode": 2}, "barrier_mode"),
]


@pytest.mark.parametrize("change, name", BAD, ids=[f"{n}={list(c.values())[-1]}" for c, n in BAD])
def test_bad_parameter_raises_clear_error(change, name):
    with pytest.raises(ValueError) as err:
        Parameters(**change)
    message = str(err.value)
    value = list(change.values())[-1]
    assert message.startswith(f"{name} = ")
    assert repr(float(value)) in message or repr(value) in message
    assert "allowed" in message
    # Nothing else breaks: a valid damper still builds and runs.
    sim = Simulator(Parameters())
    sim.advance(0.05, 0.0, 0.0)
    assert sim.state.t == 0.05


@pytest.mark.parametrize("t_end, y, v, name", [
    (0.1, math.nan, 0.0, "y"), (0.1, 0.0, math.inf, "v"), (math.nan, 0.0, 0.0, "t_end"),
    (0.0, 0.0, 0.0, "t_end"), (-1.0, 0.0, 0.0, "t_end"),
])
def test_bad_advance_raises_clear_error_and_keeps_state(t_end, y, v, name):
    sim = Simulator(Parameters())
    before = sim.snapshot()
    with pytest.raises(ValueError, match=f"^{name} = "):
        sim.advance(t_end, y, v)
    assert sim.snapshot() == before
    sim.advance(0.1, 0.0, 0.0)
    assert sim.state.t == 0.1


@pytest.mark.parametrize("barrier", [-1, 1])
@pytest.mark.parametrize("rate", [1e-13, -1e-13, 0.0, 1e-9, 1e-6])
def test_a_body_at_a_barrier_whose_rate_turns_back_within_rounding_is_not_lost(rate, barrier):
    """The impact mass on a barrier, the main mass accelerating at 2 m/s^2 to the right: the left
    barrier comes at it, the right one draws away. Leaving the left barrier at 1e-13 m/s (above
    the rate's rounding level, 3e-15), the mass is caught within rounding of its start, where the
    event function never reads the side it left for: the search saw no crossing, and the mass
    passed 0.43 mm through the barrier. It now switches where the function leaves rounding. At
    every rate: in free flight the mass is never beyond a barrier, the left barrier catches it at
    once, and the batch engine's event location (another method) finds the same onsets and state
    after a period."""
    from piezo_fmu.solver.batch import Ensemble, HarmonicHold

    params = Parameters(voltage_model=1, R_load=3.59e6)
    half = params.d / 2
    start = (-2e-3, 0.1, -2e-3 + barrier * half, 0.1 + rate)
    drive = HarmonicHold(math.sqrt(1000.0), 1e-15)  # the base at rest, to rounding
    y, v = drive.nodes()
    sim = Simulator(params.replace(p0=start[0], dp0=start[1], q0=start[2], dq0=start[3]), y0=y[0], v0=v[0])
    for k in range(drive.samples):
        sim.advance((k + 1) * drive.step, y[k], v[k])
        s = sim.state
        assert s.side != 0 or abs(s.q - s.p) <= half + 1e-12, (k, s.q - s.p)
    record = Ensemble(params, drive, [start]).advance(1)
    assert sim.metrics.impact_count == record["impacts"][0, 0] >= 1
    s = sim.state
    assert np.abs(record["sections"][0, 0] - (s.p, s.dp, s.q, s.dq)).max() < 1e-9
    first = sim.impacts[0]
    if barrier < 0:
        assert first.side == -1 and first.time < 1e-5
    else:  # into the right barrier at once, or not until the mass meets a barrier again
        assert first.time == 0.0 if rate > 0.0 else first.time > 0.01
