"""Event location on one bracket: every sign change of a polynomial on ``[0, 1]``.

Each event function (``|r| - d/2``, ``delta``, ``delta'``, ``p'``) is, on a bracket, a polynomial
of degree ``ORDER`` in the normalised time (``propagation.py``). Its sign changes are isolated
rigorously in the Bernstein basis: the number of sign variations of the Bernstein coefficients
on an interval bounds the number of roots inside it (Descartes' rule of signs), so an interval
with no variation has no root, one with exactly one variation has exactly one, and anything
else is halved (de Casteljau) until it is one or the other. A grazing double crossing - two
roots straddling an extremum inside one bracket - is therefore never missed, however close
the roots are, down to the subdivision floor ``MIN_WIDTH``; below it a pair of roots is a
tangency to rounding and is not an event. Each isolated root is then refined by a
bracketed Newton iteration to the last bit.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.rounding import EPS
from .propagation import ORDER

#: Narrowest interval (in normalised bracket time) that is still halved.
MIN_WIDTH = 2.0**-40
#: Absolute tolerance of a refined root in normalised bracket time (with 4 ulp relative).
XTOL = 2.0**-60
#: A Newton step this small (normalised time) is the last one: quadratic convergence.
NEWTON_LAST = 1e-9

_n = ORDER
# b = a @ _TO_BERNSTEIN: b_i = sum_{k<=i} C(i,k)/C(n,k) a_k.
_TO_BERNSTEIN = np.array(
    [[math.comb(i, k) / math.comb(_n, k) if k <= i else 0.0 for i in range(_n + 1)] for k in range(_n + 1)]
)


def _split_matrices(n: int) -> tuple[np.ndarray, np.ndarray]:
    """de Casteljau at 1/2 as two matrices: ``left = b @ L``, ``right = b @ R`` (degree ``n``).

    ``left_j = sum_{i<=j} C(j, i) b_i / 2^j`` and ``right_j = sum_{i>=j} C(n-j, i-j) b_i / 2^(n-j)``:
    convex combinations of the coefficients, as stable as the recursive form."""
    L = np.zeros((n + 1, n + 1))
    R = np.zeros((n + 1, n + 1))
    for j in range(n + 1):
        for i in range(j + 1):
            L[i, j] = math.comb(j, i) / 2.0**j
        for i in range(j, n + 1):
            R[i, j] = math.comb(n - j, i - j) / 2.0 ** (n - j)
    return L, R


_SPLIT_LEFT, _SPLIT_RIGHT = _split_matrices(ORDER)


def _split(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """de Casteljau at 1/2: Bernstein coefficients of the left and right halves."""
    return b @ _SPLIT_LEFT, b @ _SPLIT_RIGHT


def _sign_pattern(b: np.ndarray) -> tuple[int, int, int]:
    """Sign variations of ``b`` (zeros skipped), and the signs of its first and last non-zero
    entries (0 and 0 when all are zero)."""
    signs = np.sign(b)
    signs = signs[signs != 0]
    if signs.size == 0:
        return 0, 0, 0
    return int(np.count_nonzero(signs[1:] != signs[:-1])), int(signs[0]), int(signs[-1])


def bernstein(a: np.ndarray) -> np.ndarray:
    """Bernstein coefficients on [0, 1] of power coefficients ``a`` (last axis)."""
    return a @ _TO_BERNSTEIN


def crossings(a: np.ndarray, direction: int, b: np.ndarray | None = None, noise: float = 0.0,
              values: list[float] | None = None) -> list[float]:
    """All ``s`` in ``(0, 1]`` where the polynomial ``a`` changes sign in ``direction``.

    A root exactly at ``s = 0`` is never reported (it belongs to the previous bracket); one
    exactly at ``s = 1`` is.

    Parameters
    ----------
    a : power coefficients, ``a(s) = sum_k a[k] s^k``.
    direction : +1 for a crossing from negative to positive, -1 for positive to negative.
    b : its Bernstein coefficients, when already computed.
    noise : the rounding level of the function's values; a Bernstein coefficient within it
        counts as zero, so a function that is zero to rounding has no sign changes (rounding
        noise would otherwise look like a swarm of roots).
    values : ``b`` as a list of floats, when already made.
    """
    if b is None:
        b = bernstein(a)
    # The whole bracket first, on Python floats: it almost always has no sign change of the
    # requested kind, or exactly one, which needs no subdivision.
    if values is None:
        values = b.tolist()
    if min(values) > 0.0 or max(values) < 0.0:
        return []  # one strict sign (most event functions on most brackets)
    if values[0] == 0.0 and (min(values[1:]) > 0.0 or max(values[1:]) < 0.0):
        return []  # zero at the start, then one strict sign
    variations, first, last, f_lo, f_hi, guess = _pattern(values, noise)
    if variations < 2:
        found = []
        if variations and first == -direction and last == direction:
            found.append(_refine(a.tolist(), 0.0, 1.0, direction, f_lo, f_hi, guess))
        if f_hi == 0.0 and last == -direction:
            found.append(1.0)  # a root exactly at the right end
        return found
    if noise > 0.0:
        b = np.where(np.abs(b) <= noise, 0.0, b)
    coefficients = a.tolist()
    found: list[float] = []
    stack = [(0.0, 1.0, b)]
    while stack:
        lo, hi, piece = stack.pop()
        variations, first, last = _sign_pattern(piece)
        if variations >= 2 and hi - lo > MIN_WIDTH:
            left, right = _split(piece)
            if noise > 0.0:
                left[np.abs(left) <= noise] = 0.0
                right[np.abs(right) <= noise] = 0.0
            mid = 0.5 * (lo + hi)
            stack.append((mid, hi, right))
            stack.append((lo, mid, left))
            continue
        if first == 0:
            continue
        if variations and first == -direction and last == direction:
            # Python floats, not numpy scalars: the iteration's arithmetic is then 3 times faster.
            found.append(_refine(coefficients, lo, hi, direction, float(piece[0]), float(piece[-1])))
        # A root exactly at the right end is reported here and excluded from the next piece.
        if piece[-1] == 0.0 and last == -direction:
            found.append(hi)
    return found


def _pattern(b: list[float], noise: float) -> tuple[int, int, int, float, float, float]:
    """:func:`_sign_pattern` of Bernstein coefficients given as floats, those within ``noise`` of
    zero counted as zero; the first and last coefficients so counted; and where the control
    polygon first crosses zero (normalised time; 0.5 without a crossing), a start for Newton."""
    variations = first = last = 0
    guess = 0.5
    before = 0
    for index, value in enumerate(b):
        if value > noise:
            sign = 1
        elif value < -noise:
            sign = -1
        else:
            continue
        if not first:
            first = sign
        elif sign != last:
            if not variations:
                guess = (before + (index - before) * b[before] / (b[before] - value)) / (len(b) - 1)
            variations += 1
        last, before = sign, index
    f_lo, f_hi = b[0], b[-1]
    return (variations, first, last, (f_lo if abs(f_lo) > noise else 0.0), (f_hi if abs(f_hi) > noise else 0.0),
            guess)


def _refine(a: list[float], lo: float, hi: float, direction: int, f_lo: float, f_hi: float,
            start: float | None = None) -> float:
    """The root in ``(lo, hi)`` of a polynomial that crosses zero once there, in ``direction``.

    Newton's method on the polynomial, kept inside a shrinking bracket whose ends have the
    signs ``-direction`` (left) and ``direction`` (right); a step that leaves the bracket, or
    does not halve it fast enough, is replaced by bisection. Once a Newton step is below
    ``NEWTON_LAST`` the convergence is quadratic, so the error after it is of the order of its
    square (below 1e-17 on a bracket whose polynomial turns by at most a few radians) and it is
    the last. ``f_lo`` and ``f_hi`` are the values at the ends (the end Bernstein coefficients),
    which give the secant start, unless a ``start`` inside ``(lo, hi)`` is given (the crossing of
    the control polygon: nearer, so one or two evaluations fewer).
    """
    if start is not None and lo < start < hi:
        x = start
    else:
        x = lo + (hi - lo) * f_lo / (f_lo - f_hi) if f_lo * f_hi < 0.0 else 0.5 * (lo + hi)
    for _ in range(300):
        value, slope = _horner_with_slope(a, x)
        if value == 0.0:
            return x
        if value * direction > 0.0:
            hi = x
        else:
            lo = x
        step = value / slope if slope != 0.0 else math.inf
        new = x - step
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        elif abs(step) <= NEWTON_LAST:
            return new
        if abs(new - x) <= XTOL + 4 * EPS * abs(new) or hi - lo <= XTOL + 4 * EPS * abs(hi):
            return new
        x = new
    return x


def horner(a: list[float], s: float) -> float:
    """Value at ``s`` of the polynomial with power coefficients ``a``."""
    value = 0.0
    for coefficient in reversed(a):
        value = value * s + coefficient
    return value


def _horner_with_slope(a: list[float], s: float) -> tuple[float, float]:
    value = slope = 0.0
    for coefficient in reversed(a):
        slope = slope * s + value
        value = value * s + coefficient
    return value, slope
