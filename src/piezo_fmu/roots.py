"""Event location on one bracket: every sign change of a polynomial on ``[0, 1]``.

Each event function (``|r| - d/2``, ``delta``, ``delta'``, ``p'``) is, on a bracket, a polynomial
of degree ``ORDER`` in the normalised time (``propagation.py``). Its sign changes are isolated
rigorously in the Bernstein basis: the number of sign variations of the Bernstein coefficients
on an interval bounds the number of roots inside it (Descartes' rule of signs), so an interval
with no variation has no root, one with exactly one variation has exactly one, and anything
else is halved (de Casteljau) until it is one or the other. A grazing double crossing - two
roots straddling an extremum inside one bracket - is therefore never missed, however close
the roots are, down to the subdivision floor ``MIN_WIDTH``; below it a pair of roots is a
tangency to rounding and is not an event. Each isolated root is then refined by Brent's
method to the last bit.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from .propagation import ORDER

#: Narrowest interval (in normalised bracket time) that is still halved.
MIN_WIDTH = 2.0**-40

_n = ORDER
# b = a @ _TO_BERNSTEIN: b_i = sum_{k<=i} C(i,k)/C(n,k) a_k.
_TO_BERNSTEIN = np.array(
    [[math.comb(i, k) / math.comb(_n, k) if k <= i else 0.0 for i in range(_n + 1)] for k in range(_n + 1)]
)


def _horner(a: list[float], s: float) -> float:
    value = 0.0
    for coefficient in reversed(a):
        value = value * s + coefficient
    return value


def _split(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """de Casteljau at 1/2: Bernstein coefficients of the left and right halves."""
    n = b.size - 1
    left = np.empty_like(b)
    right = np.empty_like(b)
    work = b.copy()
    left[0] = work[0]
    right[n] = work[n]
    for j in range(1, n + 1):
        work = 0.5 * (work[:-1] + work[1:])
        left[j] = work[0]
        right[n - j] = work[-1]
    return left, right


def _sign_changes(b: np.ndarray) -> int:
    signs = np.sign(b)
    signs = signs[signs != 0]
    return int(np.count_nonzero(signs[1:] != signs[:-1]))


def has_no_root(b: np.ndarray) -> bool:
    """True when the Bernstein coefficients prove there is no root in the open interval."""
    return bool(b.min() > 0.0 or b.max() < 0.0)


def bernstein(a: np.ndarray) -> np.ndarray:
    """Bernstein coefficients on [0, 1] of power coefficients ``a`` (last axis)."""
    return a @ _TO_BERNSTEIN


def crossings(a: np.ndarray, direction: int, b: np.ndarray | None = None) -> list[float]:
    """All ``s`` in ``(0, 1]`` where the polynomial ``a`` changes sign in ``direction``.

    Parameters
    ----------
    a : power coefficients, ``a(s) = sum_k a[k] s^k``.
    direction : +1 for a crossing from negative to positive, -1 for positive to negative.
    b : its Bernstein coefficients, when already computed.

    A root exactly at ``s = 0`` is never reported (it belongs to the previous bracket); one
    exactly at ``s = 1`` is.
    """
    if b is None:
        b = bernstein(a)
    if has_no_root(b[1:]) and (b[0] == 0.0 or np.sign(b[0]) == np.sign(b[1])):
        return []
    coefficients = a.tolist()
    found: list[float] = []
    stack = [(0.0, 1.0, b)]
    while stack:
        lo, hi, piece = stack.pop()
        variations = _sign_changes(piece)
        if variations >= 2 and hi - lo > MIN_WIDTH:
            left, right = _split(piece)
            mid = 0.5 * (lo + hi)
            stack.append((mid, hi, right))
            stack.append((lo, mid, left))
            continue
        nonzero = piece[piece != 0.0]
        if nonzero.size == 0:
            continue
        first, last = np.sign(nonzero[0]), np.sign(nonzero[-1])
        if variations and first == -direction and last == direction:
            found.append(_refine(coefficients, lo, hi, direction))
        # A root exactly at the right end is reported here and excluded from the next piece.
        if piece[-1] == 0.0 and last == -direction:
            found.append(hi)
    return found


def _refine(a: list[float], lo: float, hi: float, direction: int) -> float:
    """The root in ``(lo, hi)`` of a polynomial that crosses zero once there, in ``direction``.

    The sign is ``-direction`` just right of ``lo`` and ``direction`` just left of ``hi``; an end
    value that is zero (a root shared with a neighbouring piece) or of the other sign by rounding
    is replaced by that sign, so the bracket handed to Brent's method is always valid.
    """
    f_lo = _horner(a, lo)
    f_hi = _horner(a, hi)
    tiny = 1e-300
    if np.sign(f_lo) != -direction:
        f_lo = -direction * tiny
    if np.sign(f_hi) != direction:
        f_hi = direction * tiny

    def f(s: float) -> float:
        if s == lo:
            return f_lo
        if s == hi:
            return f_hi
        return _horner(a, s)

    return brentq(f, lo, hi, xtol=1e-300, rtol=8.9e-16, maxiter=200)


def _value(s: float, a: list[float]) -> float:
    return _horner(a, s)
