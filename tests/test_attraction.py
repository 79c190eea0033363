"""Where the motion goes: the steady state reported for a start is the motion its
trajectory reaches. Each case is checked by an independent route: the FMU marched with fmpy
alone (:mod:`fmpy_march`, no harness code) from the same start, for hundreds of periods.

At 1.2 w_n the default damper has a stable two-impact orbit (1.00 mm) and the stable motion
without impacts (2.27 mm, a family: the free impact mass can rest anywhere). Newton from a
marched state that still impacts used to land on the second; the search now reports an orbit
only once the march from Newton's start is shown to go there.
"""

from __future__ import annotations

import cmath
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fmpy_march import half_swing, march

from piezo_fmu_harness.circuit import circuit_constants
from piezo_fmu_harness.periodic.attraction import follows
from piezo_fmu_harness.periodic.band import DEFAULT_AMPLITUDE, DEFAULT_VOLTAGE_MODEL, linear_transmissibility, solve_point
from piezo_fmu_harness.periodic.steady_state import Settings, Shooting

FMU = Path(__file__).resolve().parent.parent / "fmus" / "PiezoImpactDamper.fmu"
RATIO, Y = 1.2, DEFAULT_AMPLITUDE


@pytest.fixture(scope="module")
def case(instance) -> SimpleNamespace:
    """The basin map's settings at 1.2 w_n, as ``piezo-fmu basins --ratio 1.2`` sets them: the
    voltage model 1, the load ``1/(omega_c C_p)`` to 6 digits, ``Y`` = 1 mm; and a grid of
    15 x 15 starts, two linear amplitudes either way, row-major over ``p0 x p0'``."""
    values = {"voltage_model": DEFAULT_VOLTAGE_MODEL}
    values["R_load"] = float(f"{circuit_constants(instance, values)['R_opt_estimate_ohm']:.6g}")
    parameters = {**instance.model.defaults(), **values}
    M, K, C = parameters["M"], parameters["K"], parameters["C"]
    omega = RATIO * math.sqrt(K / M)
    linear = Y * float(linear_transmissibility(omega, M, K, C))
    span = 2.0 * linear
    p0, dp0 = np.linspace(-span, span, 15), np.linspace(-span * omega, span * omega, 15)
    grid = [(i * 15 + j, float(p), float(v)) for i, p in enumerate(p0) for j, v in enumerate(dp0)]
    return SimpleNamespace(values=values, omega=omega, linear=linear, grid=grid, M=M, K=K, C=C)


def settled_at_the_end(plain, omega: float) -> float:
    """The largest return of the plain march's last ten sections after one period (m, scaled)."""
    scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
    sections = plain["sections"]
    return max(float(np.max(np.abs((sections[-k] - sections[-k - 1]) * scale))) for k in range(1, 11))


def test_the_basin_start_newton_took_for_the_motion_without_impacts_ends_on_the_two_impact_orbit(instance, case):
    # Start 4 of the default map: p0 = -4.545 mm, p0' = -0.0739 m/s, the impact mass at rest in the
    # middle of the gap, base phase 0. Newton used to report the motion without impacts (2.27 mm).
    index, p0, dp0 = case.grid[4]
    assert p0 == pytest.approx(-4.545e-3, abs=1e-6) and dp0 == pytest.approx(-0.0739, abs=1e-4)
    start = [p0, dp0, p0, 0.0]
    record = solve_point(instance, index, case.values, case.omega, Y, Settings(), start, 0.0)
    assert record["status"] == "ok" and record["settled"] and record["max_multiplier"] < 1.0
    assert record["order"] == 1 and record["impacts_per_cycle"] == 2.0
    # Newton did land on the motion without impacts, and the march refused it: it impacted.
    assert any(o["impacts_per_cycle"] == 0.0 and o["reason"] == "impacts" for o in record["rejected_orbits"])

    plain = march(FMU, case.values, case.omega, Y, start, 0.0, 500)
    # The FMU marched alone ends on the orbit reported: two impacts in each of the last 100
    # periods, settled (its sections return within 1e-3 Y), the same amplitude over the last two.
    assert plain["impacts"][-100:] == [2] * 100
    assert settled_at_the_end(plain, case.omega) < 1e-3 * Y
    samples = 64
    last = slice(-2 * samples - 1, None)
    amplitude = half_swing(plain["p"][last], plain["dp"][last], plain["h"])
    assert amplitude == pytest.approx(record["amplitude"], rel=1e-5)
    assert amplitude == pytest.approx(1.00e-3, rel=1e-2)  # the two-impact orbit, not the 2.27 mm one


def test_a_start_that_never_impacts_keeps_the_motion_without_impacts(instance, case):
    # On the closed-form orbit of the main mass alone at phase 0, the impact mass at rest in the
    # middle: the transient is the base's harmonics alone, it never impacts, and Newton's orbit is
    # the response at the first check, as before the rule.
    M, K, C, w = case.M, case.K, case.C, case.omega
    response = Y * (K + 1j * C * w) / (K - M * w**2 + 1j * C * w)
    p0, dp0 = abs(response) * math.sin(cmath.phase(response)), abs(response) * w * math.cos(cmath.phase(response))
    start = [p0, dp0, p0, 0.0]
    record = solve_point(instance, 0, case.values, w, Y, Settings(), start, 0.0)
    assert record["status"] == "ok" and record["settled"] and record["order"] == 1
    assert record["impacts_per_cycle"] == 0 and record["neutral_multipliers"] == 2
    assert record["amplitude"] == pytest.approx(case.linear, rel=1e-6)
    assert record["rejected_orbits"] == [] and record["method"] == "newton"

    plain = march(FMU, case.values, w, Y, start, 0.0, 300)
    assert sum(plain["impacts"]) == 0
    last = slice(-2 * 64 - 1, None)
    assert half_swing(plain["p"][last], plain["dp"][last], plain["h"]) == pytest.approx(record["amplitude"], rel=1e-5)


def test_the_sweep_up_at_1_375_reports_the_motion_marched_from_the_previous_point(instance, case):
    # The start: the final state and phase of the default frequency response at 1.35 w_n (up; not
    # periodic, chaotic), the guess at 1.375. From it Newton used to land on the motion without
    # impacts (1.12 mm) while the sweep kept impacting. Now the point is not periodic.
    values = case.values
    state = [0.00047387443948351923, 0.03881321359605673, -0.00019218938177558407, 0.09674867271367091]
    phase, omega = 4.2215151282612835, 1.375 * math.sqrt(case.K / case.M)
    record = solve_point(instance, 0, values, omega, Y, Settings(), state, phase)
    assert record["status"] == "ok" and not record["settled"]
    assert any(o["impacts_per_cycle"] == 0.0 for o in record["rejected_orbits"])

    plain = march(FMU, values, omega, Y, state, phase, 400)
    impacts = np.array(plain["impacts"])
    # Marched alone it keeps impacting to the end; its impacts per cycle over windows as long as
    # the record's (60 periods) bracket the record's.
    assert impacts[-20:].sum() > 0
    window = record["measured_cycles"]
    rates = [impacts[k:k + window].mean() for k in range(0, len(impacts) - window + 1, 10)]
    assert min(rates) <= record["impacts_per_cycle"] <= max(rates)
    assert min(rates) > 1.0


def test_an_impact_sequence_is_followed_from_any_of_its_periods():
    assert follows([1, 2, 1, 2, 1], (2, 1)) and follows([2, 1, 2], (2, 1))
    assert follows([2, 2, 2], (2,)) and follows([0, 0], (0,))
    assert not follows([2, 2, 1, 2], (2,)) and not follows([1, 1], (2, 1)) and not follows([0, 1], (0,))


def test_returns_that_shrink_by_less_than_rounding_are_not_a_converged_march():
    # The last returns |x_k - x_(k-1)| fall by one unit in the last place over three orbits: their
    # ratio per orbit rounds to 1, the geometric tail is unbounded, not a division by zero.
    first = 2.0**-10
    returns = {2: first, 3: first, 4: first, 5: first * (1 - 2.0**-53)}
    shooting = Shooting.__new__(Shooting)
    shooting.drive = SimpleNamespace(distance=lambda a, b: returns[a])
    shooting.settings, shooting.tolerance = Settings(max_order=1), 1e-9
    assert shooting._marched_order(list(range(6))) is None
