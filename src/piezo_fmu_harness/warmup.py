"""Warming up the writers of results while a study simulates.

The main process of a sweep, a frequency response or an optimisation only waits on its workers;
what writing the results needs is imported and exercised meanwhile, so that the writing after the
last point does not start with a second and a half of imports.
"""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path

import numpy as np

from . import figures
from .analysis import save_dataset


def preload() -> threading.Thread:
    """Import and warm up, in a background thread, what writing results needs: xarray (with the
    duck-array modules it probes, dask.array among them: 0.5 s), the NetCDF engine (a tiny file
    written) and matplotlib (fonts, mathtext). About 1.5 s of imports that the main
    process, which only waits on its workers during a sweep, would otherwise spend after the last
    point, one core idle. At normal priority: on cores the workers fill it slows them by about
    half its CPU, which is less than it would cost after them. Join it before writing (whatever
    is left then counts as writing)."""
    thread = threading.Thread(target=_preload, name="preload-outputs", daemon=True)
    thread.start()
    return thread


def _preload() -> None:
    import xarray as xr

    with tempfile.TemporaryDirectory() as folder:
        save_dataset(xr.Dataset({"x": ("i", np.zeros(2))}), Path(folder) / "warm-up.nc")
    figures.warm_up()
