"""Exact propagation of a linear phase ``x' = A x`` over short brackets.

Both phases of the damper are linear with constant coefficients once the base input is a
first-order hold (docs/model.md sections 2-3). In deviation coordinates from the moving base,
``u = p - y(t)`` and ``w = q - y(t)``, the ramp of the hold is the exact particular solution,
so the state ``x = (u, w, u', w', 1)`` obeys ``x' = A x`` (the constant 1 carries the contact
offset ``d/2``). Its solution is ``x(t0 + s tau) = exp(A s tau) x(t0)``.

On a bracket of length ``tau <= THETA / rho(A)`` (``rho`` the spectral radius), the series of the
matrix exponential is summed to ``ORDER`` terms, which is exact to rounding: the first omitted
term is below ``THETA**(ORDER+1) / (ORDER+1)! ~ 2e-18`` of the state, 50 times below the
rounding of a double. Each bracket is thus a polynomial of degree ``ORDER`` in the normalised
time ``s in [0, 1]``, which makes event location (``roots.py``) and the energy integrals of the
ledger (primitives of polynomials) exact.
"""

from __future__ import annotations

import math

import numpy as np

#: Terms kept of the exponential series on one bracket.
ORDER = 24
#: Bracket length times the spectral radius of ``A``: each mode turns by at most THETA radians.
THETA = 2.0
#: Longest bracket (s) whatever ``A``: ``MAX_BRACKET**ORDER`` is far inside double range.
MAX_BRACKET = 1e3
#: Shortest bracket (s) a phase may need: ``A**ORDER / ORDER!`` would overflow near 3e-14 s,
#: and the FMU's time grid (whole nanoseconds) could not resolve the motion anyway.
MIN_BRACKET = 1e-9

_K = np.arange(ORDER + 1)
#: Coefficients of a bracket polynomial.
STATE_TERMS = ORDER + 1
#: Coefficients of the primitive of a squared bracket polynomial (degree 2 ORDER + 1).
PRIMITIVE_TERMS = 2 * ORDER + 2
#: The exponents ``k`` of :func:`powers`.
POWER_EXPONENTS = _LONG = np.arange(PRIMITIVE_TERMS, dtype=float)
#: The series is built by doubling (``LinearPhase``) up to the first power of 2 above ORDER.
_DOUBLED = 1 << ORDER.bit_length()
#: ``1 / C(m + j, m)`` for j < m, m a power of 2.
_INVERSE_BINOMIALS = {1 << i: np.array([1.0 / math.comb((1 << i) + j, j) for j in range(1 << i)])[:, None, None]
                      for i in range(ORDER.bit_length())}


class LinearPhase:
    """The exact flow of ``x' = A x`` over brackets of at most ``h`` seconds.

    Parameters
    ----------
    A : (n, n) array
        State matrix, SI units (1/s and 1/s^2 entries).
    rho : float, optional
        Its spectral radius (1/s), when known in closed form; by default from its eigenvalues.
    """

    def __init__(self, A: np.ndarray, rho: float | None = None):
        self.A = np.asarray(A, dtype=float)
        if rho is None:  # a matrix beyond double range turns at once: the integrator refuses it
            rho = float(np.max(np.abs(np.linalg.eigvals(self.A)))) if np.isfinite(self.A).all() else math.inf
        #: s, the longest bracket: each mode turns by at most THETA rad within it, and no longer
        #: than MAX_BRACKET, so that ``tau**ORDER`` stays finite for a phase that barely moves.
        self.h = THETA / rho if rho > THETA / MAX_BRACKET else MAX_BRACKET
        n = self.A.shape[0]
        terms = np.empty((_DOUBLED, n, n))
        terms[0] = np.eye(n)
        # A^k / k! by doubling: with the first m terms, A^(m+j) / (m+j)! = (A^m / m!) (A^j / j!) / C(m+j, m).
        # Beyond double range (a stiffness of 1e300) the terms overflow: the integrator refuses such a
        # phase, naming the parameters and their range, so numpy's warning would only precede it.
        m = 1
        with np.errstate(over="ignore", invalid="ignore"):
            while m <= ORDER:
                top = terms[m - 1] @ (self.A / m)
                np.matmul(top, terms[:m], out=terms[m:2 * m])
                terms[m:2 * m] *= _INVERSE_BINOMIALS[m]
                m *= 2
        # (A^k / k!) stacked so that one product gives every Taylor coefficient of x.
        self._set_terms(terms[:ORDER + 1])

    def _set_terms(self, terms: np.ndarray) -> None:
        self._terms = terms
        self._flat_terms = terms.reshape(-1, terms.shape[1])  # one matrix-vector product for all of them
        #: ``h^k``, the scaling of the coefficients on a whole bracket (the usual case).
        self._scale_h = (self.h ** _K)[:, None]

    def mirrored(self, signs: np.ndarray) -> "LinearPhase":
        """The phase of ``S A S``, ``S = diag(signs)`` (entries +-1): the same flow seen in the
        coordinates ``S x``, made by exact sign changes instead of a new series."""
        flips = np.outer(signs, signs)
        mirror = object.__new__(LinearPhase)
        mirror.A, mirror.h = self.A * flips, self.h
        mirror._set_terms(self._terms * flips)
        return mirror

    @property
    def bracket_terms(self) -> np.ndarray:
        """``(A h)^k / k!``, shape (ORDER+1, n, n): the Taylor coefficients of a whole bracket are
        ``bracket_terms @ x``."""
        return self._terms * self._scale_h[:, :, None]

    def coefficients(self, x: np.ndarray, tau: float) -> np.ndarray:
        """Taylor coefficients ``c`` with ``x(t0 + s tau) = sum_k c[k] s^k``, shape (ORDER+1, n)."""
        n = x.shape[0]
        return (self._flat_terms @ x).reshape(-1, n) * (self._scale_h if tau == self.h else (tau ** _K)[:, None])


#: ``powers(0.0)``, shared read-only by every bracket that has not moved yet.
POWERS_AT_START = np.zeros(PRIMITIVE_TERMS)
POWERS_AT_START[0] = 1.0
POWERS_AT_START.flags.writeable = False
#: ``powers(1.0)``, shared read-only by every bracket that has run to its end.
POWERS_AT_END = np.ones(PRIMITIVE_TERMS)
POWERS_AT_END.flags.writeable = False


def powers(s: float) -> np.ndarray:
    """``s^k`` for k < PRIMITIVE_TERMS: the first STATE_TERMS serve the bracket polynomials."""
    return s ** _LONG


def primitive(a: np.ndarray, weight: float = 1.0, out: np.ndarray | None = None) -> np.ndarray:
    """Coefficients (``PRIMITIVE_TERMS`` of them) of ``weight * int_0^s a``; written into ``out``
    (zero at index 0) when given."""
    if out is None:
        out = np.zeros(PRIMITIVE_TERMS)
    out[1:ORDER + 2] = weight * a / (_K + 1.0)
    return out


def primitive_of_square(a: np.ndarray, weight: float = 1.0, out: np.ndarray | None = None) -> np.ndarray:
    """Coefficients of ``weight * int_0^s a^2``, exact; written into ``out`` (zero at index 0)
    when given."""
    if out is None:
        out = np.zeros(PRIMITIVE_TERMS)
    out[1:] = weight * np.convolve(a, a) / _LONG[1:]
    return out
