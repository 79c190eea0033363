"""The filters of the generator: the FIR that shapes white noise into the target PSD, and the
high-pass with the exact double integration that turns the acceleration into the base displacement.

**Shaping FIR.** White Gaussian noise of unit variance sampled at ``fs = 1/h`` has the one-sided
PSD ``2/fs``; through a filter ``H`` it has ``|H(f)|^2 2/fs``, so ``|H(f)| = sqrt(G(f) fs / 2)``.
The FIR is designed by frequency sampling: that magnitude, with zero phase, on the grid
``j fs / N`` (``N`` taps), inverse-transformed, centred at tap ``N/2`` (linear phase, a delay
that does not matter to a stationary process) and multiplied by the periodic Hann window.
On the grid its response is then the target's magnitude smoothed over three points,
``(T_{j-1} + 2 T_j + T_{j+1}) / 4``: a smooth PSD is kept to second order in ``fs / N``, an edge of a
band is spread over two grid steps either side. ``N`` is :func:`fir_taps`:
``TAPS_PER_CORNER fs / f_low`` (even, at least ``MIN_TAPS``), so the grid step is an eighth of the
high-pass's corner ``f_low``: every feature of ``G`` above the corner is resolved.

**High-pass and double integration.** The displacement nodes ``y_k`` obey
``y_{k+1} - 2 y_k + y_{k-1} = h^2 ah_k``, ``ah`` the acceleration ``a`` through a digital
Butterworth high-pass of order :data:`HIGHPASS_ORDER` with corner ``f_low`` (bilinear transform
with a prewarped corner: four zeros at ``z = 1``). Two of those zeros cancel the double
integrator's two poles at ``z = 1`` exactly, so the filter from ``a`` to ``y`` has only the
Butterworth's poles (stable) and ``y`` stays bounded. It is built as two second-order sections
(:func:`displacement_sections`), the cancellation done by construction rather than by rounding:
section 1 is ``k (1 - z^-1)^2 / A_1(z)``, section 2 is ``h^2 / A_2(z)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft, signal

#: FIR taps per ``fs / f_low``: the design grid's step is ``f_low / TAPS_PER_CORNER``.
TAPS_PER_CORNER = 8
#: The fewest taps of a shaping FIR.
MIN_TAPS = 256
#: The most taps of a shaping FIR; it bounds ``f_low`` from below at ``TAPS_PER_CORNER fs / MAX_TAPS``.
MAX_TAPS = 2**18
#: Order of the Butterworth high-pass.
HIGHPASS_ORDER = 4


def fir_taps(fs: float, f_low: float) -> int:
    """Taps of the shaping FIR for sampling rate ``fs`` and high-pass corner ``f_low`` (Hz): the
    even number at or above ``TAPS_PER_CORNER fs / f_low``, at least ``MIN_TAPS``."""
    taps = math.ceil(TAPS_PER_CORNER * fs / f_low)
    return max(MIN_TAPS, taps + taps % 2)


def design_fir(density, step: float, taps: int) -> np.ndarray:
    """The shaping FIR (``taps`` coefficients) for the one-sided PSD ``density(f)`` at step ``step``
    (see the module's text)."""
    fs = 1.0 / step
    grid = np.arange(taps // 2 + 1) * (fs / taps)
    magnitude = np.sqrt(np.asarray(density(grid), dtype=float) * (fs / 2.0))
    impulse = np.roll(fft.irfft(magnitude, taps), taps // 2)
    return impulse * signal.get_window("hann", taps, fftbins=True)


def _pole_pairs(f_low: float, step: float) -> tuple[list, float]:
    _, poles, gain = signal.butter(HIGHPASS_ORDER, f_low, btype="highpass", fs=1.0 / step, output="zpk")
    upper = sorted((p for p in poles if p.imag > 0.0), key=abs)
    return upper, float(gain)


def highpass_sections(f_low: float, step: float) -> np.ndarray:
    """The high-pass alone as second-order sections (scipy's ``sos`` layout)."""
    (p1, p2), gain = _pole_pairs(f_low, step)
    return np.array([[gain, -2.0 * gain, gain, 1.0, -2.0 * p1.real, abs(p1) ** 2],
                     [1.0, -2.0, 1.0, 1.0, -2.0 * p2.real, abs(p2) ** 2]])


def displacement_sections(f_low: float, step: float) -> np.ndarray:
    """The filter from the acceleration ``a_k`` to the next node ``y_{k+1}`` as second-order
    sections: ``h^2 HP(z) / (1 - z^-1)^2`` with two of the high-pass's zeros cancelled exactly."""
    (p1, p2), gain = _pole_pairs(f_low, step)
    return np.array([[gain, -2.0 * gain, gain, 1.0, -2.0 * p1.real, abs(p1) ** 2],
                     [step * step, 0.0, 0.0, 1.0, -2.0 * p2.real, abs(p2) ** 2]])


def highpass_gain(f, f_low: float, step: float) -> np.ndarray:
    """``|HP(f)|^2`` of the digital Butterworth high-pass, exactly:
    ``1 / (1 + (tan(pi f_low h) / tan(pi f h))^(2 n))`` for ``0 <= f < fs/2`` (the bilinear
    transform of the analog Butterworth with its corner prewarped); 0 at ``f = 0``."""
    f = np.asarray(f, dtype=float)
    with np.errstate(divide="ignore", over="ignore"):
        ratio = math.tan(math.pi * f_low * step) / np.tan(np.pi * np.abs(f) * step)
        return np.where(f == 0.0, 0.0, 1.0 / (1.0 + ratio ** (2 * HIGHPASS_ORDER)))


def fft_length(taps: int, frame: int) -> int:
    """The FFT length of overlap-save with ``taps`` and ``frame`` new samples a block: the least
    ``2^k``, ``3 2^k`` or ``5 2^k`` that holds ``frame + taps - 1`` (scipy's FFTs are fastest there)."""
    need = frame + taps - 1
    return min(m * 2 ** max(0, math.ceil(math.log2(need / m))) for m in (1, 3, 5))
