"""The linear oracle: what the generated input does to a linear oscillator, in closed form up to
one quadrature.

The base-excited oscillator (mass ``M`` kg on a spring ``K`` N/m and a damper ``C`` N s/m to the
base) has the relative displacement ``x = p - y`` with ``M x'' + C x' + K x = -M a``; per unit base
acceleration ``H(w) = 1 / (K/M - w^2 + i w C/M)`` (the sign does not enter a PSD). Under the
generated input (:class:`~piezo_fmu_harness.excitation.generate.Excitation`, stationary part) the
one-sided PSD of ``x`` is ``|H(2 pi f)|^2 G(f) |HP(f)|^2``, ``G`` the target and ``|HP|^2`` the
high-pass's exact gain, and its variance is the integral of that over the band.

The FMU's base is the first-order hold of the nodes: its acceleration is the impulse train
``h ah_k`` at the nodes, whose PSD is ``G |HP|^2`` below ``fs/2`` and its images above; the images
(at ``fs - f`` and beyond, ``f <= fs/4``) add a fraction of order ``(f_n / (0.75 fs))^4`` of the
off-resonance response, which is left out. The discrete nodes ``y_k`` themselves obey the exact
double integration, so their PSD is ``G |HP|^2 (h / (2 sin(pi f h)))^4`` (:func:`base_displacement_psd`).

The quadrature (:func:`variance`) splits the band at every point where the density is not smooth
and maps ``RESONANCE_WIDTHS`` half-power widths either side of the resonance by
``f = f_n + gamma tan(u)``, which makes the resonant peak flat; scipy's adaptive quadrature then
reaches ``1e-10`` relative (the tests check ``1e-9`` against an independent quadrature in mpmath at
the nominal damper, ``zeta = 0.0016``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import integrate

from .inputs import number, positive

#: Half-power widths either side of the resonance integrated in the variable ``u`` (see the module's text).
RESONANCE_WIDTHS = 200.0
RELATIVE_TOLERANCE = 1e-10


def _oscillator(M, K, C) -> tuple[float, float, float]:
    M = positive("M", M, "kg")
    K = positive("K", K, "N/m")
    C = number("C", C, "N.s/m", 0.0, math.inf, why="an undamped oscillator has no bounded variance")
    return M, K, C


def relative_displacement_gain(f, M: float, K: float, C: float) -> np.ndarray:
    """``|H(2 pi f)|^2``, (m / (m/s^2))^2 = s^4: the relative displacement per unit base acceleration."""
    return _gain(f, *_oscillator(M, K, C))


def _gain(f, M: float, K: float, C: float, numerator=1.0) -> np.ndarray:
    """``numerator |H(2 pi f)|^2``; where the squares of ``|1 / H|`` leave double range (a spring
    or a damper at the edges of the FMU's ranges), from the larger part of ``1 / H`` divided out
    twice, which gives the quotient wherever it is a double (0 where ``numerator`` is)."""
    w = 2.0 * np.pi * np.asarray(f, dtype=float)
    numerator = np.asarray(numerator, dtype=float)
    with np.errstate(over="ignore", under="ignore"):
        real, imaginary = K / M - w * w, w * C / M
        denominator = real**2 + imaginary**2
    squared = np.isfinite(denominator) & (denominator >= np.finfo(float).tiny)
    if np.all(squared):
        return 1.0 / denominator * numerator
    big = np.maximum(np.abs(real), np.abs(imaginary))
    small = np.minimum(np.abs(real), np.abs(imaginary))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        ratio = np.where(big > 0.0, small / big, 0.0)
        apart = np.where(numerator == 0.0, 0.0, numerator / big / big / (1.0 + ratio * ratio))
        return np.where(squared, 1.0 / denominator * numerator, apart)


def acceleration_psd(excitation, f) -> np.ndarray:
    """``G(f) |HP(f)|^2``, (m/s^2)^2/Hz: the acceleration the FMU sees."""
    return excitation.density(f)


def base_displacement_psd(excitation, f) -> np.ndarray:
    """The one-sided PSD of the nodes ``y_k``, m^2/Hz: ``G |HP|^2 (h / (2 sin(pi f h)))^4``."""
    f = np.asarray(f, dtype=float)
    h = excitation.step
    with np.errstate(divide="ignore", invalid="ignore"):
        integrator = (h / (2.0 * np.sin(np.pi * f * h))) ** 4
    return np.where(f > 0.0, excitation.density(f) * np.where(f > 0.0, integrator, 0.0), 0.0)


def relative_displacement_psd(excitation, f, M: float, K: float, C: float) -> np.ndarray:
    """``|H(2 pi f)|^2 G(f) |HP(f)|^2``, m^2/Hz: the relative displacement ``p - y`` of the
    linear oscillator ``(M, K, C)`` on the generated base."""
    return _gain(f, *_oscillator(M, K, C), numerator=excitation.density(f))


def variance(psd, excitation, resonance: float | None = None, width: float | None = None) -> float:
    """``int psd(f) df`` over the excitation's band, by adaptive quadrature split at the
    density's breakpoints and the high-pass's corner; with ``resonance`` (Hz) and its half-power
    half-width ``width`` (Hz), the peak is integrated in ``u``, ``f = resonance + width tan(u)``."""
    excitation.density(0.0)  # refuses a record, which has no PSD
    spectrum = excitation.source
    top = spectrum.upper
    points = {0.0, top, *spectrum.breakpoints(), *(excitation.f_low * c for c in (0.5, 1.0, 2.0, 4.0))}
    near = None
    if resonance is not None:
        near = (resonance - RESONANCE_WIDTHS * width, resonance + RESONANCE_WIDTHS * width)
        points |= set(near)
    points = sorted(p for p in points if 0.0 <= p <= top)
    total = 0.0
    for a, b in zip(points[:-1], points[1:]):
        if b <= a:
            continue
        if near is not None and near[0] <= a and b <= near[1]:
            ua, ub = math.atan((a - resonance) / width), math.atan((b - resonance) / width)

            def mapped(u):
                return float(psd(resonance + width * math.tan(u))) * width / math.cos(u) ** 2

            part = integrate.quad(mapped, ua, ub, epsabs=0.0, epsrel=RELATIVE_TOLERANCE, limit=500)[0]
        else:
            part = integrate.quad(lambda f: float(psd(f)), a, b, epsabs=0.0, epsrel=RELATIVE_TOLERANCE, limit=500)[0]
        total += part
    return total


def acceleration_variance(excitation) -> float:
    """The variance of the acceleration the FMU sees, (m/s^2)^2 (stationary part)."""
    return variance(lambda f: acceleration_psd(excitation, f), excitation)


def base_displacement_variance(excitation) -> float:
    """The variance of the nodes ``y_k``, m^2 (stationary part)."""
    return variance(lambda f: base_displacement_psd(excitation, f), excitation)


def relative_displacement_variance(excitation, M: float, K: float, C: float) -> float:
    """The variance of the relative displacement ``p - y`` of the oscillator ``(M, K, C)``, m^2
    (stationary part; ``C > 0``)."""
    M, K, C = _oscillator(M, K, C)
    resonance = math.sqrt(K / M) / (2.0 * math.pi)
    width = C / M / (4.0 * math.pi)  # zeta w_n in Hz: the half-power half-width of |H|^2
    return variance(lambda f: _gain(f, M, K, C, numerator=excitation.density(f)), excitation, resonance, width)
