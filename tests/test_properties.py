"""Property-based tests of the core: random valid dampers, initial conditions, base inputs and chops.

The number of examples comes from the hypothesis profile (``tests/conftest.py``): ``ci`` runs
500, ``long`` 10 000 (``HYPOTHESIS_PROFILE=long make test``).
"""

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from piezo_fmu import EXPLICIT, Parameters, Simulator

DURATION = 0.3
EPS = 2.0**-52


def ledger_tolerance(sim, flowed: float) -> float:
    """How closely the energy ledger closes (J): to 1e-9 of the energy that flowed, and never finer
    than the energy of rounding the contact's offset, a few ulp of the gap in the barrier's
    stiffness (the balance of a body released at rest on a barrier, with some 1e-69 J of energy,
    meets that floor: rounding a position of d/2 puts about 1e-32 J in the contact)."""
    return 1e-9 * flowed + sim.barrier.K_eq * (4 * EPS * sim.params.d) ** 2


@st.composite
def dampers(draw):
    M = draw(st.floats(0.2, 10.0))
    K = draw(st.floats(10.0, 1e5))
    critical = 2 * math.sqrt(K * M)
    C = draw(st.one_of(st.just(0.0), st.floats(0.0, 2.0 * critical), st.just(critical)))
    d = draw(st.floats(1e-4, 0.05))
    p0 = draw(st.floats(-0.02, 0.02))
    q0 = p0 + draw(st.floats(-0.5, 0.5)) * d
    kw = dict(
        M=M, K=K, C=C, d=d, p0=p0, q0=q0,
        m=draw(st.floats(0.005, 1.0)) * M,
        C_eq=draw(st.one_of(st.just(0.0), st.floats(0.0, 500.0))),
        x1=draw(st.floats(0.0, 0.07)),
        dp0=draw(st.floats(-1.0, 1.0)), dq0=draw(st.floats(-1.0, 1.0)),
    )
    if draw(st.booleans()):
        kw.update(barrier_mode=EXPLICIT, M_eq=draw(st.floats(1e-4, 0.5)) * M, K_eq=draw(st.floats(1e3, 1e8)))
    return Parameters(**kw)


@st.composite
def base_inputs(draw):
    """(amplitude m, angular frequency rad/s, hold s); amplitude 0 is the base at rest."""
    amplitude = draw(st.one_of(st.just(0.0), st.floats(1e-5, 5e-3)))
    return amplitude, draw(st.floats(1.0, 300.0)), draw(st.sampled_from([1e-3, 7e-3]))


def chops(draw_sizes, duration):
    times, t = [], 0.0
    for size in draw_sizes:
        t += size
        if t >= duration:
            break
        times.append(t)
    return times + [duration]


def run(params, base, times):
    amplitude, omega, hold = base
    sim = Simulator(params)
    start = 0.0
    for t in times:
        sim.advance(t, amplitude * math.sin(omega * start), amplitude * omega * math.cos(omega * start))
        start = t
    return sim


def assert_momentum_exact_at_switches(sim):
    """Total momentum before and after every onset and separation, to 1e-14 relative."""
    M, m, M_eq = sim.params.M, sim.params.m, sim.barrier.M_eq
    for i in sim.impacts:
        scale = M * abs(i.dp_before) + m * abs(i.dq_before) + 1e-300
        assert abs((M - M_eq) * i.dp_after + (m + M_eq) * i.dq_after - M * i.dp_before - m * i.dq_before) <= 1e-14 * scale
        if not math.isnan(i.duration):
            scale = (M - M_eq) * abs(i.dp_sep_before) + (m + M_eq) * abs(i.dq_sep_before) + 1e-300
            before = (M - M_eq) * i.dp_sep_before + (m + M_eq) * i.dq_sep_before
            assert abs(M * i.dp_sep_after + m * i.dq_sep_after - before) <= 1e-14 * scale


def work_bound(sim, calls, duration):
    """Brackets a run may open: each phase's span cut into brackets, plus a restart per switch and per call."""
    switches = 2 * len(sim.impacts)
    h_min = min(sim.bracket_lengths.values())
    return duration / h_min + switches + calls + 1


def hold_times(hold, duration):
    return [min(duration, (k + 1) * hold) for k in range(int(math.ceil(duration / hold - 1e-9)))]


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(params=dampers(), base=base_inputs())
def test_random_damper_runs_with_bounded_work_exact_momentum_and_closed_ledger(params, base):
    times = hold_times(base[2], DURATION)
    sim = run(params, base, times)
    # Bounded work: the contacts per second are bounded by the contact period (docs/reliability.md).
    assert sim.brackets_opened <= work_bound(sim, len(times), DURATION)
    assert_momentum_exact_at_switches(sim)
    e = sim.energy
    flowed = e.initial + abs(e.work_base) + e.dissipated + e.total
    assert abs(e.balance_error) <= ledger_tolerance(sim, flowed)


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(params=dampers(), sizes=st.lists(st.floats(1e-6, 0.1), min_size=1, max_size=60))
def test_random_chop_of_time_changes_nothing_with_base_at_rest(params, sizes):
    times = chops(sizes, DURATION)
    chopped = run(params, (0.0, 1.0, 1.0), times)
    whole = run(params, (0.0, 1.0, 1.0), [DURATION])
    assert [(i.time, i.side, i.max_deflection) for i in chopped.impacts] == \
        [(i.time, i.side, i.max_deflection) for i in whole.impacts]
    assert chopped.state == whole.state
    a, b = chopped.metrics.as_dict(), whole.metrics.as_dict()
    for key in a:
        assert a[key] == b[key] or (math.isnan(a[key]) and math.isnan(b[key])) or \
            math.isclose(a[key], b[key], rel_tol=1e-10), key
