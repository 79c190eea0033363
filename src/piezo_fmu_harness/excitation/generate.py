"""Realizations of the base input for the FMU: nodes ``y_k`` (m) on a grid of step ``h`` (s) and
slopes ``v_k = (y_{k+1} - y_k) / h`` (m/s), the first-order hold the FMU takes
(``base_displacement = y_k``, ``base_velocity = v_k`` set at the start of step ``k``).

**The acceleration.** ``a_k`` is stationary Gaussian with the spectrum's one-sided PSD ``G(f)``:
white Gaussian noise of unit variance through the shaping FIR of :mod:`.design`, filtered by
overlap-save FFT convolution in frames of :data:`FRAME` steps. The first frame is preceded by as
many noise samples as the filter is long, so ``a_0`` is already stationary. With an envelope,
``a_k`` is multiplied by ``e(t_k)``, ``t_k = k h``. A recorded acceleration is taken as it is.

**The low-frequency treatment.** The nodes follow from the acceleration by the exact discrete
double integration combined with a causal Butterworth high-pass of order 4 at ``f_low``
(:mod:`.design`): ``y_{k+1} - 2 y_k + y_{k-1} = h^2 ah_k``, ``ah`` the high-passed ``a``. So the base
acceleration the FMU then sees, ``(y_{k+1} - 2 y_k + y_{k-1}) / h^2`` (its slope changes at the
nodes), is exactly the high-passed ``a_k``, whose PSD is ``G(f) |HP(f)|^2``
(:meth:`Excitation.density`), and the displacement is bounded. The base is at rest before
``t = 0``: ``y_{-1} = y_0 = 0``, so ``v_0 = h ah_0``, the velocity the acceleration's first
sample gives it. Start the structure at rest (``p0 = dp0 = 0``).

**Bits.** Realization ``r`` draws its noise from
``numpy.random.Generator(PCG64(SeedSequence(seed, spawn_key=(r,))))`` (the child ``r`` of
``SeedSequence(seed).spawn``), frame by frame, and every frame is filtered alone: its bits depend
on the seed, the realization, the spectrum, the step, ``f_low``, the envelope and :data:`FRAME`,
never on how many steps a call takes, which realizations are generated beside it, or how
realizations are split among workers (on one machine with one numpy and scipy: their random
streams and FFTs may change between versions).

**Memory.** A stream keeps the noise history of one filter length (``taps - 1`` values),
the nodes of one frame and four filter states (:attr:`Stream.buffers`), whatever the record's length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft, signal

from .design import (HIGHPASS_ORDER, MAX_TAPS, TAPS_PER_CORNER, design_fir, displacement_sections, fft_length,
                     fir_taps, highpass_gain)
from .envelopes import Envelope
from .inputs import STEP_TOLERANCE, number, positive, read_record, whole
from .spectra import Spectrum

#: Steps a frame: the noise is drawn, filtered and integrated in frames of this many steps.
FRAME = 16384
#: The step must resolve the spectrum: ``upper <= fs / RESOLUTION``.
RESOLUTION = 4
#: ``f_low`` unless given (Hz), or half the spectrum's ``band_start`` where that is lower.
DEFAULT_F_LOW = 0.1


@dataclass(frozen=True, eq=False)
class Record:
    """A recorded base acceleration: one realization.

    Parameters
    ----------
    step : float
        Its uniform step, s (it becomes the input step: a record is never resampled).
    acceleration : array
        m/s^2 at ``t_k = k step``, ``k = 0, 1, ...``; after its end the acceleration is zero
        (the base comes back to rest through the high-pass).
    name : str
        Where it came from (its file).
    """

    step: float
    acceleration: np.ndarray
    name: str = "record"

    def __post_init__(self):
        object.__setattr__(self, "step", positive("step", self.step, "s"))
        values = np.array(self.acceleration, dtype=float)
        if values.ndim != 1 or values.size < 2 or not np.all(np.isfinite(values)):
            raise ValueError(f"{self.name}: acceleration of shape {values.shape}; allowed: at least two finite values")
        values.setflags(write=False)
        object.__setattr__(self, "acceleration", values)

    @classmethod
    def from_csv(cls, path) -> "Record":
        """The record of a CSV file: time (s), acceleration (m/s^2), see :func:`.inputs.read_record`."""
        step, acceleration = read_record(path)
        return cls(step, acceleration, name=str(path))

    def describe(self) -> dict:
        return {"kind": "record", "source": self.name, "step_s": self.step, "samples": int(self.acceleration.size),
                "unit": "m/s^2"}


class Excitation:
    """The base input of one study: a spectrum (or a record), the step, the high-pass, the envelope
    and the seed; it hands out :class:`Stream` s of realizations.

    Parameters
    ----------
    source : Spectrum or Record
        The one-sided PSD of the acceleration (:mod:`.spectra`) or a recorded acceleration.
    step : float, optional
        The input (communication) step ``h``, s. Required with a spectrum, which it must resolve:
        ``source.upper <= 1 / (RESOLUTION h)``. With a record it is the record's step (given, it
        must equal it: a record is not resampled).
    f_low : float, optional
        The high-pass's corner, Hz (see the module's text): in
        ``[TAPS_PER_CORNER / (MAX_TAPS h), source.band_start / 2]`` with a spectrum (so the
        high-pass passes the band to 0.4% in power), in ``[TAPS_PER_CORNER / (MAX_TAPS h), 1 / (RESOLUTION h)]``
        with a record. Default ``min(DEFAULT_F_LOW, band_start / 2)``, ``DEFAULT_F_LOW`` with a record.
    envelope : Envelope, optional
        Modulates the acceleration (:mod:`.envelopes`); stationary without.
    seed : int
        ``>= 0``; realization ``r`` uses ``SeedSequence(seed, spawn_key=(r,))``.

    Attributes
    ----------
    step, f_low : float
        As given or defaulted (s, Hz).
    taps, fft_length : int
        The shaping FIR's length (:func:`.design.fir_taps`) and its overlap-save FFT's (0 for a record).
    sections : ndarray
        The filter from ``a_k`` to ``y_{k+1}`` as second-order sections (:func:`.design.displacement_sections`).
    """

    def __init__(self, source, step=None, f_low=None, envelope=None, seed=0):
        if isinstance(source, Record):
            if step is not None:
                step = positive("step", step, "s")
                if abs(step - source.step) > STEP_TOLERANCE * source.step:
                    raise ValueError(f"step = {step!r} s differs from the record's step {source.step!r} s; allowed: "
                                     "the record's step (a record is not resampled; resample it first)")
            self.step = source.step
            top, why = (1.0 / self.step) / RESOLUTION, "below the highest frequency the step resolves"
            f_low = DEFAULT_F_LOW if f_low is None else f_low
        elif isinstance(source, Spectrum):
            self.step = positive("step", step, "s")
            fs = 1.0 / self.step
            if source.upper > fs / RESOLUTION:
                raise ValueError(
                    f"the spectrum's band reaches upper = {source.upper:g} Hz, above what step = {self.step!r} s "
                    f"resolves; allowed: upper <= fs/{RESOLUTION} = {fs / RESOLUTION:g} Hz (a step of at most "
                    f"{1.0 / (RESOLUTION * source.upper):g} s, or a lower cut)")
            top, why = 0.5 * source.band_start, f"half the band's start {source.band_start:g} Hz"
            f_low = min(DEFAULT_F_LOW, top) if f_low is None else f_low
        else:
            raise ValueError(f"source = {source!r}; allowed: a spectrum (WhiteNoise, KanaiTajimi, CloughPenzien, "
                             "TablePSD) or a Record")
        fs = 1.0 / self.step
        self.source = source
        self.f_low = number("f_low", f_low, "Hz", TAPS_PER_CORNER * fs / MAX_TAPS, top, lo_open=False,
                            hi_open=False, why=f"from the slowest high-pass the step allows to {why}")
        if envelope is not None and not isinstance(envelope, Envelope):
            raise ValueError(f"envelope = {envelope!r}; allowed: None, JenningsHousnerTsai or ShinozukaSato")
        self.envelope = envelope
        self.seed = whole("seed", seed)
        self.sections = displacement_sections(self.f_low, self.step)
        self.taps = self.fft_length = 0
        self._fir_spectrum = None
        if isinstance(source, Spectrum):
            self.taps = fir_taps(fs, self.f_low)
            self.fft_length = fft_length(self.taps, FRAME)
            self._fir_spectrum = fft.rfft(design_fir(source.density, self.step, self.taps), self.fft_length)

    @property
    def realizations(self) -> float:
        """How many distinct realizations there are: 1 for a record, unbounded for a spectrum."""
        return 1 if isinstance(self.source, Record) else math.inf

    def density(self, f) -> np.ndarray:
        """The one-sided PSD, (m/s^2)^2/Hz, of the acceleration the FMU sees at ``f`` (Hz,
        ``0 <= f < fs/2``): ``G(f) |HP(f)|^2``, the stationary part (without the envelope)."""
        if not isinstance(self.source, Spectrum):
            raise ValueError("a recorded excitation has no PSD; allowed: an excitation of a spectrum")
        return self.source.density(f) * highpass_gain(f, self.f_low, self.step)

    def describe(self) -> dict:
        """JSON-safe: the source, the step, the low-frequency treatment, the filters, the envelope
        and the random numbers."""
        return {
            "source": self.source.describe(), "step_s": self.step, "sampling_Hz": 1.0 / self.step,
            "highpass": {"kind": "Butterworth, digital (bilinear, corner prewarped), causal", "order": HIGHPASS_ORDER,
                         "corner_Hz": self.f_low},
            "low_frequency_treatment": "y_{k+1} - 2 y_k + y_{k-1} = h^2 (high-passed a)_k, y_{-1} = y_0 = 0",
            "shaping_fir": None if not self.taps else {
                "taps": self.taps, "design": "frequency sampling, |H| = sqrt(G fs / 2), linear phase",
                "window": "Hann (periodic)", "overlap_save_fft": self.fft_length, "frame_steps": FRAME},
            "envelope": None if self.envelope is None else self.envelope.describe(),
            "seed": self.seed, "random_numbers": "standard normal, numpy PCG64 of SeedSequence(seed, spawn_key=(r,))",
        }

    def stream(self, realization: int = 0) -> "Stream":
        """Realization ``realization`` (``>= 0``; 0 only for a record), from ``t = 0``."""
        return Stream(self, realization)

    def chunk(self, realizations) -> "Chunk":
        """Several realizations side by side, each generated alone."""
        return Chunk(self, realizations)


class _Noise:
    """Frames of the shaped acceleration of one realization (overlap-save): each block is the
    last ``taps - 1`` noise samples and ``FRAME`` new ones, zero-padded in front to the FFT length."""

    def __init__(self, excitation: Excitation, realization: int):
        sequence = np.random.SeedSequence(excitation.seed, spawn_key=(realization,))
        self.rng = np.random.Generator(np.random.PCG64(sequence))
        self.n, self.spectrum = excitation.fft_length, excitation._fir_spectrum
        self.history = self.rng.standard_normal(excitation.taps - 1)  # the noise before a_0

    def next_frame(self) -> np.ndarray:
        block = np.zeros(self.n)
        block[self.n - FRAME - self.history.size:self.n - FRAME] = self.history
        self.rng.standard_normal(out=block[self.n - FRAME:])
        self.history = block[self.n - self.history.size:].copy()
        return fft.irfft(fft.rfft(block) * self.spectrum, self.n)[self.n - FRAME:]


class _Recorded:
    """Frames of a record, zeros after its end."""

    def __init__(self, record: Record):
        self.values, self.at, self.history = record.acceleration, 0, np.zeros(0)

    def next_frame(self) -> np.ndarray:
        frame = np.zeros(FRAME)
        part = self.values[self.at:self.at + FRAME]
        frame[:part.size] = part
        self.at += FRAME
        return frame


class Stream:
    """One realization, handed out step by step (see the module's text)."""

    def __init__(self, excitation: Excitation, realization: int):
        self.excitation = excitation
        self.realization = whole("realization", realization, 0,
                                 0 if isinstance(excitation.source, Record) else None)
        if isinstance(excitation.source, Record):
            self._source = _Recorded(excitation.source)
        else:
            self._source = _Noise(excitation, self.realization)
        self._state = np.zeros((2, 2))
        # The nodes of the last frame (at first only y_0 = 0); the current node is _nodes[_at].
        self._nodes, self._at = np.zeros(1), 0
        self._frames = 0
        #: Steps taken so far: the current node is ``y_position``, at ``t = position h``.
        self.position = 0

    def _next_nodes(self) -> np.ndarray:
        """The next frame's nodes ``y_{k0+1} .. y_{k0+FRAME}`` from its accelerations ``a_{k0} ..``."""
        a = self._source.next_frame()
        envelope = self.excitation.envelope
        if envelope is not None:
            a = a * envelope((self._frames * FRAME + np.arange(FRAME)) * self.excitation.step)
        nodes, self._state = signal.sosfilt(self.excitation.sections, a, zi=self._state)
        self._frames += 1
        return nodes

    def take(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """The next ``count`` steps: ``(y, v)``, ``y`` the ``count + 1`` nodes (m) from the current
        one (the last node of the previous call) and ``v`` the ``count`` slopes (m/s)."""
        count = whole("count", count)
        y = np.empty(count + 1)
        filled = 0
        while True:
            n = min(self._nodes.size - self._at, count + 1 - filled)
            y[filled:filled + n] = self._nodes[self._at:self._at + n]
            filled += n
            if filled == count + 1:
                self._at += n - 1
                break
            self._nodes, self._at = self._next_nodes(), 0
        self.position += count
        return y, (y[1:] - y[:-1]) / self.excitation.step

    @property
    def buffers(self) -> dict:
        """The sizes (values) of what the stream keeps between calls: the noise history, the
        nodes of the current frame, the filter state."""
        return {"noise_history": int(self._source.history.size), "frame_nodes": int(self._nodes.size),
                "filter_state": int(self._state.size)}


class Chunk:
    """Realizations ``realizations`` side by side: :meth:`take` returns ``(count + 1, n)`` nodes and
    ``(count, n)`` slopes, column ``j`` realization ``realizations[j]``, generated as if alone."""

    def __init__(self, excitation: Excitation, realizations):
        self.realizations = [whole("realization", r) for r in realizations]
        self.streams = [excitation.stream(r) for r in self.realizations]

    def take(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """The next ``count`` steps of every realization, as :meth:`Stream.take`: arrays of shape
        ``(count + 1, n)`` and ``(count, n)``, each realization's column contiguous (Fortran order;
        ``numpy.ascontiguousarray`` makes each step's row contiguous instead)."""
        count = whole("count", count)
        y = np.empty((len(self.streams), count + 1))
        v = np.empty((len(self.streams), count))
        for j, stream in enumerate(self.streams):
            y[j], v[j] = stream.take(count)
        return y.T, v.T
