"""Results as datasets: NetCDF written and read back with their units, and the bands where a
condition holds along a coordinate."""

from __future__ import annotations

from pathlib import Path


def save_dataset(ds, path: Path) -> str:
    """Write NetCDF with the first engine available (h5netcdf, netCDF4, scipy); return it."""
    for engine in ("h5netcdf", "netcdf4", "scipy"):
        try:
            ds.to_netcdf(path, engine=engine)
            return engine
        except (ImportError, ValueError):
            continue
    raise RuntimeError("no NetCDF engine: install h5netcdf (with h5py) or netCDF4")


def open_dataset(path: Path):
    import xarray as xr

    return xr.load_dataset(path)


def bands(ratios, mask) -> list[list[float]]:
    """Runs of consecutive ``True`` in ``mask`` as ``[first ratio, last ratio]``."""
    runs, start = [], None
    for k, inside in enumerate(list(mask) + [False]):
        if inside and start is None:
            start = k
        elif not inside and start is not None:
            runs.append([float(ratios[start]), float(ratios[k - 1])])
            start = None
    return runs
