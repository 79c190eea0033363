"""Results as datasets: NetCDF written and read back with their units, tables written as CSV with
each column's unit in its name (``amplitude_m``, ``omega_rad_per_s``: :func:`csv_frame`), and the
bands where a condition holds along a coordinate."""

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


#: How a unit is written at the end of a CSV column's name; a column without one is a count, a label,
#: a ratio or another number without a unit (the units ``1``).
UNIT_SUFFIXES = {"m": "m", "m/s": "m_per_s", "m/s^2": "m_per_s2", "rad/s": "rad_per_s", "rad": "rad", "s": "s",
                 "kg": "kg", "N": "N", "V": "V", "W": "W", "J": "J", "Ohm": "ohm", "F": "F", "cm/s": "cm_per_s",
                 "periods": "periods", "1/period": "per_period", "%": "percent"}
#: Names that say their unit already, in words.
SAID = {"s": ("seconds",), "periods": ("periods",)}


def unit_suffix(unit) -> str:
    """The suffix ``unit`` adds to a CSV column's name (``_m``, ``_m_per_s``), or ``""`` for none."""
    if unit in (None, "", "1"):
        return ""
    return "_" + UNIT_SUFFIXES.get(unit, str(unit).replace("/", "_per_").replace(" ", "_"))


def with_units(name: str, unit) -> str:
    """``name`` with its unit's suffix, unless it ends with it already (``R_load_ohm``)."""
    suffix = unit_suffix(unit)
    if not suffix or name.endswith(suffix) or name.endswith(SAID.get(unit, ())):
        return name
    return name + suffix


def csv_frame(frame, units: dict):
    """``frame`` with each column named with its unit (``units``: name -> unit, e.g. a Dataset's
    ``units`` attributes, :func:`units_of`): the CSVs' one convention (docs/harness.md)."""
    return frame.rename(columns={name: with_units(name, units.get(name)) for name in frame.columns})


def units_of(ds) -> dict:
    """The ``units`` attribute of each of ``ds``'s variables and coordinates."""
    return {name: ds[name].attrs.get("units") for name in [*ds.data_vars, *ds.coords]}
