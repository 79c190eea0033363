"""How long the starts take to settle, and whether what is left when the budget runs out persists:
the survival curve of the unresolved starts, the escape rate of a chaotic transient, the
mean transient lifetime with its 95% interval, and the plateau.

A start is **resolved** at the period its trajectory was seen reaching an orbit (or the motion
without impacts); one that was not resolved within the ``budget`` of periods is **censored** there.
The share of the starts still unresolved after ``t`` periods is the survival curve ``S(t)``. A
chaotic transient (a chaotic saddle that the trajectories leave at random) shows as an exponential
decay; what is left as the decay flattens out is an attractor that is not periodic:

    S(t) = S_inf + (1 - S_inf) exp(-kappa (t - t0)),   t > t0 (the onset),

among the starts still unresolved at the onset ``t0`` (before it the approach to the orbits is not
a random escape). :func:`escape` fits it by maximum likelihood (a mixture "cure" model: a start is
either on the plateau, with probability ``S_inf``, or a transient with an exponential lifetime),
with resolved starts contributing their lifetimes and censored ones the probability of outliving
the budget. Without a plateau (``S_inf = 0``) the estimate is the censored exponential's,
``kappa = resolved / time at risk``. The intervals are profile-likelihood intervals (the likelihood
ratio within the chi-square(1) quantile 3.84); the mean transient lifetime is ``1 / kappa``.

**The plateau is shown** (the motion left **persists**) only when all three hold:

- the likelihood ratio test of a plateau against a pure exponential decay rejects it at 5%
  (statistic above 2.71: the chi-bar-square of a parameter on its boundary); or, when no start
  resolved after the onset at all, the lifetime's 95% lower bound ``E / 3.69`` (``E`` the periods
  at risk) is at least :data:`REACH` budgets (19.5): at the slowest escape the data allow, a start
  still on the motion at the budget leaves it within a march as long again with odds below one in
  :data:`PURE` (``1 - exp(-1 / REACH) = 1 / PURE``). A march twice as long (``tools/persistence.py``)
  then finds it still there but for those odds;
- the transient has died out: the fit, at its slowest rate (the interval's low end), leaves fewer
  than one in :data:`PURE` of the unresolved starts still on the transient at the budget;
- the curve is flat at its end: the starts that resolved in the second half of the budget are not
  more than a Poisson count with the fit's expectation allows (one-sided, 5%). Starts that are
  still arriving late say that the decay is slower than one exponential, not that an attractor is
  there.

Otherwise the starts left are **undecided**: the budget did not say where they go.

The harness reads nothing but the FMU here: this module handles numbers only.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: chi-square(1) at 95%: the profile-likelihood interval.
CHI2_95 = 3.841458820694124
#: The chi-bar-square (50:50 mixture of 0 and chi-square(1)) at 5%: a plateau on its boundary.
CHIBAR_05 = 2.705543454095404
#: -ln(0.025): the 95% upper bound of a Poisson rate from no events is this over the exposure.
NONE_SEEN = 3.6888794541139363
#: At the budget at most one in this many unresolved starts may still be on the transient.
PURE = 20
#: With no escape seen, the lifetime's 95% lower bound needed, in budgets (see the module's text).
REACH = -1.0 / math.log1p(-1.0 / PURE)
#: The onset of the exponential decay, as a fraction of the budget, unless given.
ONSET = 0.05


@dataclass(frozen=True)
class Escape:
    """The fit of one drive's survival curve (periods are forcing periods).

    ``starts``: starts counted (set aside ones are not); ``at_risk``: unresolved at the onset;
    ``resolved``: of those, resolved within the budget; ``undecided``: unresolved at the budget;
    ``exposure``: periods at risk after the onset, summed; ``rate`` (1/period) and ``lifetime``
    (periods, the mean transient lifetime) with their 95% intervals (None where the data cannot
    bound them); ``plateau``: the share of the starts at risk on the plateau, with its interval;
    ``statistic``: the likelihood ratio of a plateau; ``late``: starts resolved in the second half
    of the budget and ``late_expected`` the fit's expectation; ``persists``: the plateau is shown
    (see the module's text)."""

    starts: int
    budget: int
    onset: int
    at_risk: int
    resolved: int
    undecided: int
    exposure: float
    rate: float | None
    rate_low: float | None
    rate_high: float | None
    lifetime: float | None
    lifetime_low: float | None
    lifetime_high: float | None
    plateau: float
    plateau_low: float
    plateau_high: float
    statistic: float
    late: int
    late_expected: float
    persists: bool

    def to_dict(self) -> dict:
        return asdict(self)


def survival(periods, resolved, budget: int, times=None) -> tuple[np.ndarray, np.ndarray]:
    """The share ``S(t)`` of the starts still unresolved after ``t`` periods, at ``times`` (by
    default every period from 0 to the budget). ``periods``: when each start was resolved, or the
    budget for the others; ``resolved``: which were."""
    periods, resolved = np.asarray(periods, float), np.asarray(resolved, bool)
    times = np.arange(int(budget) + 1) if times is None else np.asarray(times, float)
    if not len(periods):
        return times, np.full(len(times), math.nan)
    ended = np.sort(periods[resolved])
    return times, 1.0 - np.searchsorted(ended, times, side="right") / len(periods)


def _loglik(kappa: float, pi: float, times: np.ndarray, censored: int, span: float) -> float:
    k = len(times)
    if kappa <= 0.0:
        return 0.0 if k == 0 else -math.inf
    a = math.exp(-kappa * span)
    value = k * math.log(kappa) - kappa * float(times.sum()) if k else 0.0
    if k and pi > 0.0:
        value += k * math.log1p(-pi) if pi < 1.0 else -math.inf
    if censored:
        value += censored * math.log(pi + (1.0 - pi) * a) if pi + (1.0 - pi) * a > 0 else -math.inf
    return value


def _best_pi(kappa: float, k: int, censored: int, span: float) -> float:
    """The plateau that maximises the likelihood at the rate ``kappa`` (closed form)."""
    n = k + censored
    a = math.exp(-kappa * span)
    if a >= 1.0:
        return 0.0
    return min(max(censored / n - k * a / (n * (1.0 - a)), 0.0), 1.0)


def _profile(kappa: float, times, censored: int, span: float, plateau: bool) -> float:
    pi = _best_pi(kappa, len(times), censored, span) if plateau else 0.0
    return _loglik(kappa, pi, times, censored, span)


def _maximise(f, lo: float, hi: float) -> float:
    """The maximiser of a unimodal ``f`` of ``log kappa`` on ``[lo, hi]`` (golden section)."""
    from scipy.optimize import minimize_scalar

    grid = np.linspace(lo, hi, 121)
    values = np.array([f(x) for x in grid])
    j = int(np.nanargmax(values))
    a, b = grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]
    found = minimize_scalar(lambda x: -f(x), bounds=(a, b), method="bounded", options={"xatol": 1e-10})
    return float(found.x) if -found.fun >= values[j] else float(grid[j])


def _edge(f, top: float, inside: float, outside: float) -> float | None:
    """Where ``f`` (of ``log kappa``) falls to ``top - CHI2_95 / 2`` between ``inside`` and
    ``outside``; None when it does not."""
    from scipy.optimize import brentq

    target = top - 0.5 * CHI2_95
    g = lambda x: f(x) - target  # noqa: E731
    if g(outside) > 0:
        return None
    return float(brentq(g, min(inside, outside), max(inside, outside), xtol=1e-12))


def escape(periods, resolved, budget: int, onset: int | None = None) -> Escape:
    """Fit the survival curve of one drive's starts (see the module's text). ``periods``: when each
    start was resolved, or ``budget`` for the others; ``resolved``: which were; ``onset``: the period
    from which the decay is fitted (``ONSET`` of the budget by default)."""
    from scipy.stats import poisson

    periods, resolved = np.asarray(periods, float), np.asarray(resolved, bool)
    budget = int(budget)
    if budget < 2:
        raise ValueError(f"budget = {budget!r} periods is out of range; allowed range [2, inf)")
    onset = int(round(ONSET * budget)) if onset is None else int(onset)
    if not 0 <= onset < budget:
        raise ValueError(f"onset = {onset!r} periods is out of range; allowed range [0, {budget}) (below the budget)")
    if (resolved & (periods > budget)).any():
        raise ValueError(f"periods: a start resolved after the budget ({budget}); allowed range [0, budget]")
    risk = ~resolved | (periods > onset)
    times = periods[risk & resolved] - onset
    censored = int((risk & ~resolved).sum())
    k, n = len(times), int(risk.sum())
    span = float(budget - onset)
    exposure = float(times.sum()) + censored * span
    half = onset + 0.5 * span
    late = int((resolved & (periods > half)).sum())
    if n == 0:
        return Escape(len(periods), budget, onset, 0, 0, 0, 0.0, None, None, None, None, None, None, math.nan,
                      math.nan, math.nan, 0.0, 0, 0.0, False)
    if k == 0:
        # Nothing escaped after the onset: the rate is bounded above only.
        high = NONE_SEEN / exposure
        low_life = 1.0 / high
        persists = low_life >= REACH * budget
        return Escape(len(periods), budget, onset, n, 0, censored, exposure, 0.0, 0.0, high, None, low_life, None,
                      1.0, _plateau_low_without_escapes(n), 1.0, math.inf, 0, 0.0, persists)
    # The pure exponential, and the model with a plateau.
    kappa0 = k / exposure
    ll0 = _loglik(kappa0, 0.0, times, censored, span)
    lo, hi = math.log(kappa0) - 12.0, math.log(kappa0) + 12.0
    f = lambda x: _profile(math.exp(x), times, censored, span, True)  # noqa: E731
    x_best = _maximise(f, lo, hi)
    ll1 = max(f(x_best), ll0)
    if ll1 == ll0:
        x_best = math.log(kappa0)
    kappa = math.exp(x_best)
    pi = _best_pi(kappa, k, censored, span) if ll1 > ll0 else 0.0
    statistic = max(2.0 * (ll1 - ll0), 0.0)
    x_low, x_high = _edge(f, ll1, x_best, lo), _edge(f, ll1, x_best, hi)
    rate_low = math.exp(x_low) if x_low is not None else None
    rate_high = math.exp(x_high) if x_high is not None else None
    pi_low, pi_high = _plateau_interval(times, censored, span, ll1, pi)
    # Has the transient died out, and is the end of the curve flat?
    slowest = rate_low if rate_low is not None else 0.0
    alive = n * (1.0 - pi) * math.exp(-slowest * span)
    at_half = n * (1.0 - pi) * math.exp(-kappa * 0.5 * span)
    late_expected = at_half * (1.0 - math.exp(-kappa * 0.5 * span))
    flat = late == 0 or poisson.sf(late - 1, late_expected) >= 0.05
    persists = bool(statistic > CHIBAR_05 and pi > 0 and alive * PURE < max(censored, 1) and flat)
    lifetime = 1.0 / kappa
    return Escape(len(periods), budget, onset, n, k, censored, exposure, kappa, rate_low, rate_high, lifetime,
                  1.0 / rate_high if rate_high else None, 1.0 / rate_low if rate_low else None, pi, pi_low, pi_high,
                  statistic, late, late_expected, persists)


def _plateau_low_without_escapes(n: int) -> float:
    """The 95% lower bound of a proportion of ``n`` out of ``n`` (Clopper-Pearson)."""
    return float(0.025 ** (1.0 / n))


def _plateau_interval(times, censored: int, span: float, top: float, pi_hat: float) -> tuple[float, float]:
    """The profile-likelihood interval of the plateau (the rate maximised at each plateau, on a fine
    grid of ``log kappa``: the likelihood is in closed form)."""
    k, total = len(times), float(np.sum(times))
    centre = math.log(k / (total + censored * span))
    kappa = np.exp(np.linspace(centre - 8.0, centre + 8.0, 1201))[:, None]
    pi = np.linspace(0.0, 1.0 - 1e-9, 201)[None, :]
    with np.errstate(divide="ignore"):
        value = k * np.log(kappa) - kappa * total + k * np.log1p(-pi)
        if censored:
            value = value + censored * np.log(pi + (1.0 - pi) * np.exp(-kappa * span))
    profile = value.max(axis=0)
    inside = pi[0][profile >= top - 0.5 * CHI2_95]
    if not len(inside):
        return pi_hat, pi_hat
    step = float(pi[0, 1])
    return max(0.0, min(float(inside.min()) - 0.5 * step, pi_hat)), min(1.0, max(float(inside.max()) + 0.5 * step, pi_hat))


def counts(escape_: Escape) -> dict:
    """The JSON-safe record of a fit, floats rounded to what they mean."""
    out = {}
    for name, value in escape_.to_dict().items():
        if isinstance(value, float) and not math.isfinite(value):
            value = None
        out[name] = value
    return out
