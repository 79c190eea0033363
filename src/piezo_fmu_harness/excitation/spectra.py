"""One-sided power spectral densities of the base acceleration.

**Convention.** ``G(f)`` is the one-sided PSD of the base acceleration per hertz: unit
``(m/s^2)^2/Hz``, ``f >= 0`` in Hz, and the variance is ``int_0^inf G(f) df``. A two-sided
density per rad/s ``S(w)`` (Clough and Penzien's and Lutes and Sarkani's ``S_0`` of the
Kanai-Tajimi model) is ``G = 4 pi S``: :func:`one_sided_per_hz` converts.

Each spectrum is zero outside ``[lower, upper]`` (Hz): the band it is generated over. White noise
has its band; a table its first and last frequency; Kanai-Tajimi and Clough-Penzien reach 0 Hz
(``lower = 0``) and are cut at ``upper``, :data:`DEFAULT_UPPER` unless given: their densities fall
only as ``1/f^2``, so a sampled record needs a cut, and 25 Hz is the usual upper end of engineering
ground-motion content (the cut leaves out 4.5% of the firm-soil Kanai-Tajimi variance, which
:meth:`Spectrum.rms` does not count). At the low end, Kanai-Tajimi's ``G(0) = G0`` gives the ground
velocity and displacement no finite variance (Clough-Penzien's second filter is the classical
remedy); here the generator's high-pass (:mod:`.generate`) keeps the displacement bounded, and it
must pass the spectrum from :attr:`Spectrum.band_start` up.

**Soil presets** (:data:`KANAI_TAJIMI_SOILS`, :data:`CLOUGH_PENZIEN_SOILS`; ``omega`` rad/s):

- Kanai-Tajimi, firm soil: ``omega_g = 15.6``, ``zeta_g = 0.6``, the values of Kanai (1957) and
  Tajimi (1960) that Clough and Penzien quote for firm ground; medium and soft soil:
  ``omega_g = 10, zeta_g = 0.4`` and ``omega_g = 5, zeta_g = 0.2``, the ground filters of Der
  Kiureghian and Neuenhofer (1992, *Earthq. Eng. Struct. Dyn.* 21, 713-740);
- Clough-Penzien, firm, medium and soft soil, from Der Kiureghian and Neuenhofer (1992):
  ``(omega_g, zeta_g, omega_f, zeta_f) = (15, 0.6, 1.5, 0.6), (10, 0.4, 1.0, 0.6), (5, 0.2, 0.5, 0.6)``.

The level (``G0``, the bedrock white noise's one-sided PSD) is not part of a soil: it sets the
intensity, and :meth:`Spectrum.scaled` sweeps it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import integrate, optimize

from .inputs import number, positive, read_table, table_rows

#: Where Kanai-Tajimi and Clough-Penzien are cut unless told (Hz).
DEFAULT_UPPER = 25.0
CONVENTION = "one-sided PSD of the base acceleration per hertz: variance = integral of G(f) df over f >= 0"
UNIT = "(m/s^2)^2/Hz"

#: ``(omega_g rad/s, zeta_g)`` of the Kanai-Tajimi ground filter by soil (see the module's text).
KANAI_TAJIMI_SOILS = {"firm": (15.6, 0.6), "medium": (10.0, 0.4), "soft": (5.0, 0.2)}
#: ``(omega_g rad/s, zeta_g, omega_f rad/s, zeta_f)`` of Clough-Penzien by soil (Der Kiureghian and Neuenhofer 1992).
CLOUGH_PENZIEN_SOILS = {"firm": (15.0, 0.6, 1.5, 0.6), "medium": (10.0, 0.4, 1.0, 0.6), "soft": (5.0, 0.2, 0.5, 0.6)}


def one_sided_per_hz(two_sided_per_rad: float) -> float:
    """``G0 = 4 pi S0``: a two-sided density per rad/s as the one-sided density per Hz used here."""
    return 4.0 * math.pi * two_sided_per_rad


class Spectrum:
    """What every spectrum offers (the subclasses are frozen dataclasses).

    Attributes
    ----------
    level : float
        The PSD value that scales the shape, (m/s^2)^2/Hz (see each kind).
    lower, upper : float
        The band, Hz: the density is zero outside ``[lower, upper]``.
    """

    kind = "spectrum"
    level: float
    lower: float
    upper: float

    def shape(self, f: np.ndarray) -> np.ndarray:  # the density inside the band
        raise NotImplementedError

    def density(self, f) -> np.ndarray:
        """``G(f)``, (m/s^2)^2/Hz, at the frequencies ``f`` (Hz, any shape); zero outside the band."""
        f = np.asarray(f, dtype=float)
        inside = (f >= self.lower) & (f <= self.upper)
        return np.where(inside, self.shape(np.where(inside, f, self.upper)), 0.0)

    def parameters(self) -> dict:
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-safe: the kind, every parameter with its unit, the band, the RMS and the convention."""
        return {"kind": self.kind, "convention": CONVENTION, "unit": UNIT, **self.parameters(),
                "lower_Hz": self.lower, "upper_Hz": self.upper, "rms_m_per_s2": self.rms()}

    def scaled(self, level: float) -> "Spectrum":
        """The same shape at another ``level`` ((m/s^2)^2/Hz): the density times ``level / self.level``."""
        return replace(self, level=positive("level", level, UNIT))

    def breakpoints(self) -> tuple:
        """The frequencies (Hz) inside the band where the density is not smooth (for quadrature)."""
        return (self.lower, self.upper)

    def rms(self) -> float:
        """The RMS acceleration over the band, ``sqrt(int G df)``, m/s^2 (before the generator's high-pass)."""
        inside = np.geomspace(max(self.lower, 1e-6 * self.upper), self.upper, 13)
        points = sorted({*self.breakpoints(), *inside.tolist()})
        total = sum(integrate.quad(lambda f: float(self.density(f)), a, b, epsabs=0.0, epsrel=1e-11, limit=400)[0]
                    for a, b in zip(points[:-1], points[1:]))
        return math.sqrt(total)

    def peak(self) -> float:
        """The frequency (Hz) where the density is largest."""
        grid = np.geomspace(max(self.lower, self.upper * 1e-4), self.upper, 4001)
        k = int(np.argmax(self.density(grid)))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        found = optimize.minimize_scalar(lambda f: -float(self.density(f)), bounds=(a, b), method="bounded",
                                         options={"xatol": 1e-9 * b})
        return float(found.x) if self.density(found.x) >= self.density(grid[k]) else float(grid[k])

    @property
    def band_start(self) -> float:
        """Where the band that the generator's high-pass must pass begins (Hz): ``lower`` where the
        density is cut below (white noise, a table), its :meth:`peak` where it reaches 0 Hz
        (Kanai-Tajimi, Clough-Penzien)."""
        return self.lower if self.lower > 0.0 else self.peak()


@dataclass(frozen=True)
class WhiteNoise(Spectrum):
    """Band-limited white noise: ``G(f) = level`` for ``fmin <= f <= fmax``, zero outside.

    Parameters
    ----------
    level : float
        ``G0``, (m/s^2)^2/Hz, > 0.
    fmin, fmax : float
        The band, Hz: ``0 < fmin < fmax`` (a band from 0 Hz has no bounded displacement).
    """

    level: float
    fmin: float
    fmax: float
    kind = "white"

    def __post_init__(self):
        object.__setattr__(self, "level", positive("level", self.level, UNIT))
        fmax = positive("fmax", self.fmax, "Hz")
        object.__setattr__(self, "fmin", number("fmin", self.fmin, "Hz", 0.0, fmax, why="below fmax"))
        object.__setattr__(self, "fmax", fmax)

    lower = property(lambda self: self.fmin)
    upper = property(lambda self: self.fmax)

    def shape(self, f):
        return np.full_like(f, self.level)

    def parameters(self):
        return {"level_m2_per_s4_per_Hz": self.level, "fmin_Hz": self.fmin, "fmax_Hz": self.fmax}

    def rms(self):
        return math.sqrt(self.level * (self.fmax - self.fmin))


def _filter(r2: np.ndarray, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """``((1 - r^2)^2 + 4 zeta^2 r^2, 4 zeta^2 r^2)`` of a ground filter at ``r^2``."""
    damping = 4.0 * zeta * zeta * r2
    return (1.0 - r2) ** 2 + damping, damping


@dataclass(frozen=True)
class KanaiTajimi(Spectrum):
    """Kanai-Tajimi ground acceleration: white noise at bedrock through a soil layer.

    ``G(f) = level (1 + 4 zeta_g^2 r^2) / ((1 - r^2)^2 + 4 zeta_g^2 r^2)``, ``r = 2 pi f / omega_g``,
    for ``0 <= f <= upper``.

    Parameters
    ----------
    level : float
        ``G0``, the bedrock white noise's one-sided PSD, (m/s^2)^2/Hz, > 0.
    omega_g : float
        The ground's frequency, rad/s, > 0.
    zeta_g : float
        The ground's damping ratio, > 0.
    upper : float
        The cut, Hz (default :data:`DEFAULT_UPPER`).
    """

    level: float
    omega_g: float
    zeta_g: float
    upper: float = DEFAULT_UPPER
    lower: float = field(default=0.0, init=False)
    kind = "kanai-tajimi"

    def __post_init__(self):
        for name, unit in (("level", UNIT), ("omega_g", "rad/s"), ("zeta_g", ""), ("upper", "Hz")):
            object.__setattr__(self, name, positive(name, getattr(self, name), unit))

    @classmethod
    def soil(cls, name: str, level: float, upper: float = DEFAULT_UPPER) -> "KanaiTajimi":
        """The preset ground filter of soil ``name`` (``firm``, ``medium``, ``soft``) at ``level``."""
        return cls(level, *_preset(KANAI_TAJIMI_SOILS, name), upper=upper)

    def shape(self, f):
        r2 = (2.0 * math.pi * f / self.omega_g) ** 2
        denominator, damping = _filter(r2, self.zeta_g)
        return self.level * (1.0 + damping) / denominator

    def parameters(self):
        return {"level_m2_per_s4_per_Hz": self.level, "omega_g_rad_per_s": self.omega_g, "zeta_g": self.zeta_g}


@dataclass(frozen=True)
class CloughPenzien(KanaiTajimi):
    """Clough-Penzien ground acceleration: Kanai-Tajimi through a second filter that takes away
    the low frequencies (so that the ground displacement has a finite variance).

    ``G(f) = G_KT(f) r_f^4 / ((1 - r_f^2)^2 + 4 zeta_f^2 r_f^2)``, ``r_f = 2 pi f / omega_f``.

    Parameters
    ----------
    level, omega_g, zeta_g : float
        As for :class:`KanaiTajimi`.
    omega_f : float, optional
        The high-pass filter's frequency, rad/s, > 0; default ``0.1 omega_g``, the ratio of every
        preset.
    zeta_f : float
        Its damping ratio, > 0 (default 0.6, every preset's).
    upper : float
        The cut, Hz (default :data:`DEFAULT_UPPER`).
    """

    omega_f: float | None = None
    zeta_f: float = 0.6
    kind = "clough-penzien"

    def __post_init__(self):
        super().__post_init__()
        if self.omega_f is None:
            object.__setattr__(self, "omega_f", 0.1 * self.omega_g)
        for name, unit in (("omega_f", "rad/s"), ("zeta_f", "")):
            object.__setattr__(self, name, positive(name, getattr(self, name), unit))

    @classmethod
    def soil(cls, name: str, level: float, upper: float = DEFAULT_UPPER) -> "CloughPenzien":
        """The preset filters of soil ``name`` (``firm``, ``medium``, ``soft``) at ``level``."""
        omega_g, zeta_g, omega_f, zeta_f = _preset(CLOUGH_PENZIEN_SOILS, name)
        return cls(level, omega_g, zeta_g, upper=upper, omega_f=omega_f, zeta_f=zeta_f)

    def shape(self, f):
        r2 = (2.0 * math.pi * f / self.omega_f) ** 2
        denominator, _ = _filter(r2, self.zeta_f)
        return super().shape(f) * r2 * r2 / denominator

    def parameters(self):
        return {**super().parameters(), "omega_f_rad_per_s": self.omega_f, "zeta_f": self.zeta_f}


def _preset(table: dict, name: str) -> tuple:
    if name not in table:
        raise ValueError(f"soil = {name!r} is not a preset; allowed: {', '.join(table)}")
    return table[name]


@dataclass(frozen=True, eq=False)
class TablePSD(Spectrum):
    """A PSD given as a table, interpolated log-log (a straight line between the points on
    log-log axes, the dB/octave segments of a random-vibration test profile), zero outside
    ``[frequencies[0], upper]``. Its ``level`` is its largest PSD value; :meth:`scaled` multiplies
    every value.

    Parameters
    ----------
    frequencies : array
        Hz, positive, strictly increasing, at least two.
    densities : array
        One-sided PSD of acceleration at each frequency, (m/s^2)^2/Hz, positive.
    upper : float
        The cut, Hz, in ``(frequencies[0], frequencies[-1]]`` (default: the last frequency).
    name : str
        Where the table came from (its file), for :meth:`describe`.
    """

    frequencies: np.ndarray
    densities: np.ndarray
    upper: float = math.nan
    name: str = "table"
    kind = "table"

    def __post_init__(self):
        f = np.array(self.frequencies, dtype=float)
        g = np.array(self.densities, dtype=float)
        table_rows(f, g, where=self.name)
        f.setflags(write=False)
        g.setflags(write=False)
        object.__setattr__(self, "frequencies", f)
        object.__setattr__(self, "densities", g)
        upper = f[-1] if isinstance(self.upper, float) and math.isnan(self.upper) else self.upper
        object.__setattr__(self, "upper", number("upper", upper, "Hz", f[0], f[-1], hi_open=False,
                                                 why="inside the table's frequencies"))

    @classmethod
    def from_csv(cls, path, upper: float = math.nan) -> "TablePSD":
        """The table of a CSV file: frequency (Hz), PSD ((m/s^2)^2/Hz), see :func:`.inputs.read_table`."""
        frequencies, densities = read_table(path)
        return cls(frequencies, densities, upper=upper, name=str(path))

    lower = property(lambda self: float(self.frequencies[0]))
    level = property(lambda self: float(self.densities.max()))

    def scaled(self, level):
        factor = positive("level", level, UNIT) / self.level
        return TablePSD(self.frequencies, self.densities * factor, self.upper, self.name)

    def shape(self, f):
        return np.exp(np.interp(np.log(f), np.log(self.frequencies), np.log(self.densities)))

    def breakpoints(self):
        inside = self.frequencies[self.frequencies < self.upper]
        return tuple(float(x) for x in inside) + (self.upper,)

    def rms(self):
        # Each segment is a power law G1 (f/f1)^s: integrated exactly.
        points = np.array(self.breakpoints())
        g = self.density(points)
        f1, f2, g1, g2 = points[:-1], points[1:], g[:-1], g[1:]
        s = np.log(g2 / g1) / np.log(f2 / f1)
        with np.errstate(divide="ignore", invalid="ignore"):
            power = np.where(np.abs(s + 1.0) > 1e-12, g1 * f1 / (s + 1.0) * ((f2 / f1) ** (s + 1.0) - 1.0),
                             g1 * f1 * np.log(f2 / f1))
        return math.sqrt(float(power.sum()))

    def parameters(self):
        return {"source": self.name, "interpolation": "log-log", "frequencies_Hz": self.frequencies.tolist(),
                "densities_m2_per_s4_per_Hz": self.densities.tolist(), "level_m2_per_s4_per_Hz": self.level}
