"""Scalar root finding for the model's transcendental equations (the cantilever's frequency
equation, eq. 18) and for the solver's refinements of roots it has already bracketed.

Pure Python: the run-time core needs numpy only.
"""

from __future__ import annotations

from .rounding import EPS


def bracketed(f, lo: float, hi: float, xtol: float = 0.0) -> float:
    """The root of ``f`` in ``[lo, hi]``, where ``f(lo)`` and ``f(hi)`` have opposite signs (or one
    is zero), to the last bits: the bracket shrinks until its width is below
    ``xtol + 4 eps |x|``. False position with the Illinois halving, and a bisection whenever a
    step does not halve the bracket, so it converges superlinearly and never worse than
    bisection. Pure Python: the core's runtime needs numpy only."""
    f_lo, f_hi = f(lo), f(hi)
    if f_lo == 0.0:
        return lo
    if f_hi == 0.0:
        return hi
    if (f_lo < 0.0) == (f_hi < 0.0):
        raise ValueError(f"f({lo!r}) = {f_lo!r} and f({hi!r}) = {f_hi!r} do not bracket a root")
    side, bisect = 0, False
    for _ in range(400):
        width = hi - lo
        if width <= xtol + 4 * EPS * max(abs(lo), abs(hi)):
            break
        x = 0.5 * (lo + hi) if bisect else (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
        fx = f(x)
        if fx == 0.0:
            return x
        if (fx < 0.0) == (f_lo < 0.0):
            lo, f_lo = x, fx
            if side == -1:
                f_hi *= 0.5  # Illinois: the end that stays gets half its weight
            side = -1
        else:
            hi, f_hi = x, fx
            if side == 1:
                f_lo *= 0.5
            side = 1
        # A false-position step that did not halve the bracket: bisect once, then start afresh.
        bisect = not bisect and hi - lo > 0.5 * width
        if bisect:
            side = 0
    return lo if abs(f_lo) <= abs(f_hi) else hi
