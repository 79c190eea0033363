"""Closed form, impacting: the symmetric two-impact orbit of Masri and Caughey (1966)
under base excitation (tests/masri_caughey.py, independent of the project) against the
harness's orbit through the FMU as the contact stiffens (K_eq x 1, 10, 100, 1000 at one
restitution coefficient), in amplitude, impact velocity and stability (docs/validation.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from masri_caughey import System, admissible_orbits, monodromy, multipliers, simulate
from masri_caughey_fmu import CASES, FACTORS, closed_form, measure_restitution, table


@pytest.fixture(scope="module")
def rows(instance):
    return table(instance)


# -- the closed form on its own --------------------------------------------------------------------

@pytest.mark.parametrize("case", list(CASES))
def test_the_closed_form_orbit_is_a_periodic_orbit_of_the_ideal_impact_model(case):
    system, orbit, _ = closed_form(case, 0.6)
    assert orbit.admissible()
    x0 = orbit.state_after()
    half, _ = simulate(system, x0, orbit.t0, system.period / 4)
    back, _ = simulate(system, half, orbit.t0 + system.period / 4, system.period)
    assert np.max(np.abs(back - half)) < 1e-12


@pytest.mark.parametrize("case", list(CASES))
def test_the_closed_form_multipliers_are_those_of_the_simulated_period_map(case):
    # Central differences of the event-by-event simulation, at a section in flight.
    system, orbit, mu = closed_form(case, 0.6)
    t = orbit.t0 + system.period / 4
    x, _ = simulate(system, orbit.state_after(), orbit.t0, system.period / 4)
    jac = np.zeros((4, 4))
    for j in range(4):
        dx = np.zeros(4)
        dx[j] = 1e-8
        jac[:, j] = (simulate(system, x + dx, t, system.period)[0]
                     - simulate(system, x - dx, t, system.period)[0]) / 2e-8
    numeric = np.linalg.eigvals(jac)
    numeric = numeric[np.argsort(-np.abs(numeric))]
    assert np.allclose(np.abs(numeric), np.abs(mu), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("case", list(CASES))
def test_a_perturbation_follows_the_linearised_period_map(case):
    # 30 periods of the event-by-event simulation against the closed-form Jacobian's powers.
    system, orbit, mu = closed_form(case, 0.6)
    offset = system.period / 4
    x, _ = simulate(system, orbit.state_after(), orbit.t0, offset)
    jac = monodromy(orbit, offset)
    assert np.allclose(np.sort(np.abs(np.linalg.eigvals(jac))), np.sort(np.abs(mu)), rtol=1e-9)
    delta = np.array([1e-9, 0.0, 0.0, 0.0])
    y, predicted = x + delta, delta.copy()
    for n in range(30):
        y, _ = simulate(system, y, orbit.t0 + offset + n * system.period, system.period)
        predicted = jac @ predicted
    assert np.allclose(y - x, predicted, rtol=0, atol=1e-3 * np.max(np.abs(predicted)))
    # It leaves an unstable orbit and comes back to a stable one.
    assert (np.max(np.abs(y - x)) > 1e-9) == (abs(mu[0]) > 1.0)


def test_the_two_cases_are_one_stable_and_one_unstable():
    assert abs(closed_form("stable", 0.6)[2][0]) < 1.0 < abs(closed_form("unstable", 0.6)[2][0])


def test_without_impact_losses_and_damping_the_multipliers_lie_on_the_unit_circle_or_pair_up():
    # C = 0, e = 1: the period map conserves phase-space volume, the multipliers' product is 1.
    system = System(1.0, 1000.0, 0.0, 0.1, 8e-3, 1.0, 1e-3, 1.2 * math.sqrt(1000.0))
    for orbit in admissible_orbits(system):
        assert abs(np.prod(multipliers(orbit))) == pytest.approx(1.0, rel=1e-9)


# -- the FMU and the harness against it -------------------------------------------------------------

def test_the_contact_gives_the_same_restitution_at_every_stiffness(instance):
    e = [measure_restitution(instance, factor) for factor in FACTORS]
    assert 0.3 < e[0] < 0.9
    assert np.allclose(e, e[0], rtol=1e-9, atol=0)


@pytest.mark.parametrize("case", list(CASES))
def test_the_harness_orbit_converges_to_the_closed_form_as_the_contact_stiffens(rows, case):
    mine = [r for r in rows if r["case"] == case]
    assert [r["factor"] for r in mine] == list(FACTORS)
    for key in ("amplitude", "impact_velocity", "max_multiplier"):
        errors = [abs(r[key] / r[key + "_closed"] - 1.0) for r in mine]
        # The contact lasts ~pi / sqrt(K_eq / mu): errors fall ~sqrt(10) a decade of K_eq.
        assert all(b < 0.5 * a for a, b in zip(errors, errors[1:])), (key, errors)
        assert errors[-1] < 2e-3, (key, errors)


@pytest.mark.parametrize("case", list(CASES))
def test_the_harness_and_the_closed_form_agree_on_stability(rows, case):
    mine = [r for r in rows if r["case"] == case]
    for r in mine:
        assert r["stable"] == r["stable_closed"] == (case == "stable"), r
