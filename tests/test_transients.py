"""The survival curve and the escape-rate estimator on synthetic lifetimes whose law is
known: the estimator recovers the rate within its interval, its interval covers the true rate as
often as it says, a plateau is found where there is one and only there; and an undecided start is
never called chaotic without a plateau nor with a negative exponent."""

from __future__ import annotations

import numpy as np
import pytest

from piezo_fmu_harness.starts.attractors import merge, verdict
from piezo_fmu_harness.starts.transients import PURE, REACH, escape, survival
from piezo_fmu_harness.studies.bifurcation.study import CLOUD


def lifetimes(rng, n: int, kappa: float, budget: int, plateau: float = 0.0):
    """``n`` starts whose transients last an exponential time of rate ``kappa`` (a share ``plateau``
    never leaves), resolved at the whole period after their escape, censored at ``budget``."""
    life = np.ceil(rng.exponential(1.0 / kappa, n))
    life[rng.random(n) < plateau] = np.inf
    resolved = life <= budget
    return np.where(resolved, life, budget), resolved


def test_the_estimator_recovers_a_known_escape_rate_within_its_interval():
    kappa, budget = 1.0 / 660, 6000
    periods, resolved = lifetimes(np.random.default_rng(3), 500, kappa, budget)
    fit = escape(periods, resolved, budget, onset=0)
    assert fit.rate_low < kappa < fit.rate_high
    assert fit.lifetime_low < 660 < fit.lifetime_high
    assert fit.lifetime == pytest.approx(1.0 / fit.rate)
    assert fit.lifetime_high / fit.lifetime_low < 1.3  # 500 escapes: an interval of about +-9%
    assert fit.plateau == 0.0 and not fit.persists


def test_its_interval_covers_the_true_rate_about_95_times_in_100():
    """Over 200 seeds, with censoring (a budget of 1.5 lifetimes), the 95% interval covers the true
    rate between 90% and 99% of the time (a binomial(200, 0.95) count lies in 180..198 with
    probability above 0.999)."""
    kappa, budget = 1.0 / 400, 600
    rng = np.random.default_rng(11)
    covered = 0
    for _ in range(200):
        periods, resolved = lifetimes(rng, 120, kappa, budget)
        fit = escape(periods, resolved, budget, onset=0)
        covered += fit.rate_low <= kappa <= fit.rate_high
    assert 180 <= covered <= 198


def test_a_plateau_is_shown_where_a_share_never_leaves_and_its_share_is_recovered():
    kappa, budget = 1.0 / 300, 4000
    periods, resolved = lifetimes(np.random.default_rng(5), 400, kappa, budget, plateau=0.25)
    fit = escape(periods, resolved, budget, onset=0)
    assert fit.persists
    assert fit.plateau_low < 0.25 < fit.plateau_high
    assert fit.lifetime_low < 300 < fit.lifetime_high


def test_starts_still_arriving_late_are_no_plateau():
    """Lifetimes slower than one exponential (the cube of an exponential: starts keep arriving to the
    end of the budget, as at 1.275 w_n): what is left at the budget does not persist."""
    rng = np.random.default_rng(7)
    life = np.ceil(700 * rng.exponential(1.0, 500) ** 3)
    budget = 4000
    resolved = life <= budget
    fit = escape(np.where(resolved, life, budget), resolved, budget)
    assert fit.undecided > 50 and not fit.persists


def test_too_short_a_budget_for_the_lifetime_shows_no_plateau():
    """A lifetime ten times the budget: most starts are left at the budget, yet nothing persists."""
    kappa, budget = 1.0 / 6000, 600
    periods, resolved = lifetimes(np.random.default_rng(9), 500, kappa, budget)
    fit = escape(periods, resolved, budget, onset=0)
    assert fit.undecided > 400 and not fit.persists
    assert fit.lifetime_low < 6000 < fit.lifetime_high


def test_with_no_escape_at_all_only_a_long_enough_exposure_persists():
    """No escape in a budget shows persistence only from a lifetime's lower bound of REACH budgets:
    the bifurcation's cloud (its point and CLOUD companions) can show it, 17 trajectories cannot."""
    budget = 1000
    cloud = escape(np.full(CLOUD + 1, budget), np.zeros(CLOUD + 1, bool), budget)
    few = escape(np.full(17, budget), np.zeros(17, bool), budget)
    assert cloud.persists and cloud.lifetime_low >= REACH * budget and cloud.lifetime is None
    assert not few.persists and few.lifetime_low < REACH * budget
    # the odds that a start on the motion at the budget leaves it within as long again
    assert 1.0 - np.exp(-budget / (REACH * budget)) == pytest.approx(1.0 / PURE)


def test_a_transient_of_eight_budgets_does_not_pass_for_a_persisting_motion():
    """The bifurcation's point at 0.5226 w_n: a chaotic transient of about 8 budgets, from which a
    cloud of 17 showed no escape within one budget (a cloud of 17 does so 13% of the time). Of 200
    clouds of the bifurcation's size with lifetimes drawn with that mean, fewer than 1 in 20 is
    called persisting; of 200 on a motion that never ends, every one."""
    budget, kappa = 1000, 1.0 / 8000
    rng = np.random.default_rng(31)
    transient = sum(escape(*lifetimes(rng, CLOUD + 1, kappa, budget), budget).persists for _ in range(200))
    attractor = sum(escape(*lifetimes(rng, CLOUD + 1, kappa, budget, plateau=1.0), budget).persists
                    for _ in range(200))
    assert transient < 200 / PURE and attractor == 200


def test_the_survival_curve_counts_the_starts_unresolved_after_t_periods():
    t, s = survival([10, 20, 20, 50], [True, True, True, False], 50, [0, 10, 19, 20, 50])
    assert list(s) == [1.0, 0.75, 0.75, 0.25, 0.25]


@pytest.mark.parametrize("budget, onset, words", [(1, None, "budget = 1"), (100, 100, "onset = 100"),
                                                   (100, -1, "onset = -1")])
def test_bad_input_is_refused_with_the_parameter_and_its_range(budget, onset, words):
    with pytest.raises(ValueError, match=words):
        escape([1, 2], [True, False], budget, onset)


def _chunk(rng, persisting: bool, exponent: float, interval: float):
    """A chunk of 300 starts of one drive: 200 resolved on an orbit within 2000 periods, 100 left at
    the budget, either arriving to the end (a transient) or not since period 700 (a plateau)."""
    last = 700 if persisting else 2000
    resolved = [{"label": 0, "periods": int(p), "index": j, "group": 0}
                for j, p in enumerate(np.sort(rng.integers(20, last, 200)))]
    left = [{"label": -1, "periods": 2000, "index": 200 + j, "group": 0, "exponent": exponent,
             "exponent_low": exponent - interval, "exponent_high": exponent + interval, "line_share": 0.2}
            for j in range(100)]
    orbit = {"kind": "orbit", "group": 0, "order": 1, "impacts": [2], "impacts_per_cycle": 2.0,
             "sections": [[1e-4, 0.0, 0.0, 0.0]], "sides": [0], "amplitude": 1e-3}
    return {"starts": resolved + left, "attractors": [orbit]}


@pytest.mark.parametrize("persisting, exponent, interval, kind", [
    (False, 0.3, 0.05, "undecided"),                 # starts still arriving: no plateau, no chaos
    (True, 0.3, 0.05, "chaotic"),                    # a plateau and an exponent above 0
    (True, 0.02, 0.05, "undecided"),                 # a plateau, but the exponent's interval holds 0
    (True, -0.028, 0.005, "undecided (converging)"),  # a start once called chaotic: converging, never chaos
    (False, -0.028, 0.005, "undecided (converging)"),
])
def test_an_undecided_start_is_chaotic_only_on_a_plateau_with_a_positive_exponent(persisting, exponent, interval,
                                                                                   kind):
    chunk = _chunk(np.random.default_rng(2), persisting, exponent, interval)
    found, starts = merge([chunk], [(40.0, 1e-3)])
    left = [r for r in starts.values() if r["label"] == -1]
    assert {r["motion"] for r in left} == {kind}
    record = found[left[0]["attractor"]]
    assert record["kind"] == ("chaotic" if kind == "chaotic" else "undecided")
    assert record["transients"]["persists"] == persisting
    assert not any(r["motion"] in ("chaotic", "quasi-periodic") and r["exponent"] < 0 for r in starts.values()
                   if r["label"] == -1)


def test_a_negative_exponent_is_never_chaotic_whatever_the_plateau():
    class Plateau:
        persists = True

    for exponent in np.linspace(-0.5, -0.001, 20):
        record = {"exponent": exponent, "exponent_low": 2 * exponent, "exponent_high": 0.5 * exponent,
                  "line_share": 1.0}
        assert verdict(record, Plateau()) == "undecided (converging)"


def test_the_window_measures_bound_the_exponent_and_tell_a_line_spectrum_from_a_broad_one():
    """The statistics the verdict reads (``piezo_fmu.solver.batch.attractors.measures``): per-period log
    stretches of mean 0.3 and of mean -0.02 give exponents whose 95% intervals hold their means and
    exclude 0; section samples on two incommensurate lines have a line share above 0.9, white noise
    one well below it."""
    from piezo_fmu.solver.batch.attractors.measures import line_share, statistics

    rng = np.random.default_rng(4)
    periods = 200
    logs = np.stack([0.3 + rng.normal(0, 0.5, periods), -0.02 + rng.normal(0, 0.02, periods)], axis=1)
    k = np.arange(periods)[:, None]
    lines = 1e-3 * (np.sin(2 * np.pi * 0.1234 * k) + 0.5 * np.sin(2 * np.pi * 0.3071 * k))
    noise = 1e-3 * rng.normal(0, 1, (periods, 1))
    samples = np.concatenate([lines, noise], axis=1)
    ones = np.ones((periods, 2))
    m = statistics(logs, 2e-3 * ones, -2e-3 * ones, 2 * ones, samples)
    assert m["exponent_low"][0] < 0.3 < m["exponent_high"][0] and m["exponent_low"][0] > 0
    assert m["exponent_low"][1] < -0.02 < m["exponent_high"][1] < 0
    assert m["line_share"][0] > 0.9 > 0.5 > m["line_share"][1]
    assert (m["impacts_per_cycle"] == 2).all() and (m["modulation"] == 0).all()
    assert np.isnan(line_share(samples[:10])).all()
