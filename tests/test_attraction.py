"""Where the motion goes (issue 26): the steady state reported for a start is the motion its
trajectory reaches, as the FMU marched with fmpy alone (:mod:`plain_march`) shows it."""

from __future__ import annotations

from types import SimpleNamespace

from piezo_fmu_harness.periodic.steady_state import Settings, Shooting


def test_returns_that_shrink_by_less_than_rounding_are_not_a_converged_march():
    # The last returns |x_k - x_(k-1)| fall by one unit in the last place over three orbits: their
    # ratio per orbit rounds to 1, the geometric tail is unbounded, not a division by zero.
    first = 2.0**-10
    returns = {2: first, 3: first, 4: first, 5: first * (1 - 2.0**-53)}
    shooting = Shooting.__new__(Shooting)
    shooting.drive = SimpleNamespace(distance=lambda a, b: returns[a])
    shooting.settings, shooting.tolerance = Settings(max_order=1), 1e-9
    assert shooting._marched_order(list(range(6))) is None
