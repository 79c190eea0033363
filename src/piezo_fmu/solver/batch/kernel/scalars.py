"""numpy's rules for scalars, as the kernel needs them: ``maximum``, ``minimum`` and ``sign`` (NaN
in, NaN out), and the two special values."""

import math

from .registry import source

INF = math.inf
NAN = math.nan


@source(inline=True)
def fmax(a, b):
    """numpy's ``maximum``: NaN when either is."""
    if a != a or b != b:
        return NAN
    return a if a >= b else b


@source(inline=True)
def fmin(a, b):
    """numpy's ``minimum``: NaN when either is."""
    if a != a or b != b:
        return NAN
    return a if a <= b else b


@source(inline=True)
def sign(x):
    """numpy's ``sign``: -1, +1, or ``x`` itself when it is 0.0, -0.0 or NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x
