"""Random base excitation for the FMU: stationary Gaussian base acceleration of a given one-sided
PSD (or a recorded acceleration), turned into the FMU's inputs ``base_displacement`` and
``base_velocity`` (the first-order hold the harness drives it with), streamed.

- :mod:`.spectra`: the one-sided PSDs ``G(f)`` of the base acceleration, (m/s^2)^2/Hz: band-limited
  white noise, Kanai-Tajimi, Clough-Penzien (with soil presets), a table from a CSV file;
- :mod:`.envelopes`: modulating envelopes for earthquake-like records;
- :mod:`.inputs`: the checks and the CSV readers.

It reads neither the FMU nor the simulation core: numpy and scipy only.
"""

from .envelopes import Envelope, JenningsHousnerTsai, ShinozukaSato
from .spectra import (CLOUGH_PENZIEN_SOILS, KANAI_TAJIMI_SOILS, CloughPenzien, KanaiTajimi, Spectrum, TablePSD,
                      WhiteNoise, one_sided_per_hz)

__all__ = ["Envelope", "JenningsHousnerTsai", "ShinozukaSato", "CLOUGH_PENZIEN_SOILS", "KANAI_TAJIMI_SOILS",
           "CloughPenzien", "KanaiTajimi", "Spectrum", "TablePSD", "WhiteNoise", "one_sided_per_hz"]
