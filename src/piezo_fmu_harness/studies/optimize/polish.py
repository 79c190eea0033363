"""The polish of the optimiser's best design (``--polish``): Nelder-Mead in the unit box, on the
optimiser's own objective (:mod:`.search`)."""

from __future__ import annotations

import numpy as np


def polish_simplex(func, x0, bounds, constraints=()):
    """The polish of the search's best design: Nelder-Mead within the bounds, in coordinates
    scaled to the unit box (the parameters' scales differ by orders of magnitude), from a simplex
    of 2% of each range. Derivative-free: the objective is only as smooth as its steady states
    or free decays, and finite differences of a value exact to 1e-12 make gradients of noise.
    Stops when the simplex spans 1e-7 of each range and 1e-11 in J."""
    from scipy.optimize import minimize

    lower, upper = np.asarray(bounds.lb, float), np.asarray(bounds.ub, float)
    span = upper - lower
    start = (np.asarray(x0, float) - lower) / span
    simplex = [start] + [np.clip(start + 0.02 * np.eye(len(start))[i] * (1 if start[i] < 0.98 else -1), 0, 1)
                         for i in range(len(start))]
    result = minimize(lambda u: func(lower + np.clip(u, 0.0, 1.0) * span), start, method="Nelder-Mead",
                      bounds=[(0.0, 1.0)] * len(start),
                      options={"initial_simplex": np.array(simplex), "xatol": 1e-7, "fatol": 1e-11,
                               "maxfev": 100 * len(start)})
    result.x = lower + np.clip(result.x, 0.0, 1.0) * span
    return result
