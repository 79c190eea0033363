"""Random base excitation for the FMU: stationary Gaussian base acceleration of a given one-sided
PSD (or a recorded acceleration), turned into the FMU's inputs ``base_displacement`` and
``base_velocity`` (the first-order hold the harness drives it with), streamed.

- :mod:`.spectra`: the one-sided PSDs ``G(f)`` of the base acceleration, (m/s^2)^2/Hz: band-limited
  white noise, Kanai-Tajimi, Clough-Penzien (with soil presets), a table from a CSV file;
- :mod:`.envelopes`: modulating envelopes for earthquake-like records;
- :mod:`.design`: the shaping FIR and the high-pass with the exact double integration;
- :mod:`.generate`: :class:`Excitation`, its :class:`Stream` s and :class:`Chunk` s of
  realizations, and :class:`Record` (a recorded acceleration);
- :mod:`.replay`: a realization as the rows fmpy's ``input=`` replays, and their CSV;
- :mod:`.oracle`: the PSD and variance of a linear oscillator's response to the generated input;
- :mod:`.inputs`: the checks and the CSV readers.

It reads neither the FMU nor the simulation core: numpy and scipy only.

Example
-------
>>> from piezo_fmu_harness.excitation import Excitation, KanaiTajimi
>>> excitation = Excitation(KanaiTajimi.soil("firm", level=0.01), step=0.004, seed=7)
>>> y, v = excitation.stream(0).take(1000)   # nodes (1001,) m and slopes (1000,) m/s
>>> y.shape, v.shape
((1001,), (1000,))
"""

from .envelopes import Envelope, JenningsHousnerTsai, ShinozukaSato
from .generate import FRAME, Chunk, Excitation, Record, Stream
from .oracle import (base_displacement_variance, relative_displacement_psd, relative_displacement_variance,
                     acceleration_variance)
from .replay import read_replay_csv, replay_rows, write_replay_csv
from .spectra import (CLOUGH_PENZIEN_SOILS, KANAI_TAJIMI_SOILS, CloughPenzien, KanaiTajimi, Spectrum, TablePSD,
                      WhiteNoise, one_sided_per_hz)

__all__ = ["Envelope", "JenningsHousnerTsai", "ShinozukaSato", "FRAME", "Chunk", "Excitation", "Record", "Stream",
           "acceleration_variance", "base_displacement_variance", "relative_displacement_psd",
           "relative_displacement_variance", "read_replay_csv", "replay_rows", "write_replay_csv",
           "CLOUGH_PENZIEN_SOILS", "KANAI_TAJIMI_SOILS", "CloughPenzien", "KanaiTajimi", "Spectrum", "TablePSD",
           "WhiteNoise", "one_sided_per_hz"]
