"""The checks of the excitation's parameters and its two CSV files, with the messages they refuse with.

Every refusal is a ``ValueError`` whose message names the parameter (or the file and its line),
the value and what is allowed, as the FMU's own refusals do; the CLI turns it into exit status 2.

The CSV files (a PSD table, a recorded acceleration) are plain text: two comma-separated numeric
columns a line, an optional first line of column names, blank lines and lines starting with ``#``
ignored. Nothing else is read from them.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

import numpy as np


def _interval(lo: float, hi: float, lo_open: bool, hi_open: bool, unit: str) -> str:
    left, right = ("(" if lo_open else "["), (")" if hi_open else "]")
    return f"{left}{lo:g}, {hi:g}{right}" + (f" {unit}" if unit else "")


def number(name: str, value, unit: str, lo: float = -math.inf, hi: float = math.inf,
           lo_open: bool = True, hi_open: bool = True, why: str = "") -> float:
    """``value`` as a float inside ``lo .. hi`` (open or closed ends), or a ``ValueError`` that
    names ``name``, the value and the allowed range (``why``, when given, says where the range
    comes from)."""
    allowed = _interval(lo, hi, lo_open, hi_open, unit)
    tail = f"; allowed range {allowed}" + (f" ({why})" if why else "")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} = {value!r} is not a number{tail}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} = {value!r} is not finite{tail}")
    above = value > lo if lo_open else value >= lo
    below = value < hi if hi_open else value <= hi
    if not (above and below):
        raise ValueError(f"{name} = {value!r}" + (f" {unit}" if unit else "") + f" is out of range{tail}")
    return value


def positive(name: str, value, unit: str) -> float:
    """``value`` > 0 and finite."""
    return number(name, value, unit, 0.0, math.inf)


def whole(name: str, value, lowest: int = 0, highest: int | None = None) -> int:
    """``value`` as an int, ``lowest <= value`` (and ``<= highest`` when given)."""
    allowed = f"whole numbers from {lowest}" + (f" to {highest}" if highest is not None else " up")
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} = {value!r} is not a whole number; allowed: {allowed}")
    if value < lowest or (highest is not None and value > highest):
        raise ValueError(f"{name} = {value!r} is out of range; allowed: {allowed}")
    return int(value)


def _parse(path: Path, columns: tuple[str, str]) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The two numeric columns of a CSV file and the line number of each row."""
    where = str(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise ValueError(f"{where}: cannot be read ({error.strerror or error}); allowed: a readable CSV file of "
                         f"{columns[0]}, {columns[1]}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{where}: is not a text file; allowed: a CSV of two numeric columns "
                         f"({columns[0]}, {columns[1]})") from None
    first, second, lines = [], [], []
    header_allowed = True
    for number_, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = [cell.strip() for cell in stripped.split(",")]
        if len(cells) != 2:
            raise ValueError(f"{where}, line {number_}: {len(cells)} columns ({stripped!r}); allowed: exactly two, "
                             f"{columns[0]} and {columns[1]}, separated by a comma")
        try:
            values = [float(cell) for cell in cells]
        except ValueError:
            if header_allowed:  # the first line may name the columns
                header_allowed = False
                continue
            raise ValueError(f"{where}, line {number_}: {stripped!r} is not two numbers; allowed: numeric "
                             f"{columns[0]} and {columns[1]} (only the first line may be a header)") from None
        header_allowed = False
        for cell, value, column in zip(cells, values, columns):
            if not math.isfinite(value):
                raise ValueError(f"{where}, line {number_}: {column} = {cell} is not finite; allowed: finite numbers")
        first.append(values[0])
        second.append(values[1])
        lines.append(number_)
    if len(first) < 2:
        raise ValueError(f"{where}: {len(first)} data rows; allowed: at least 2 rows of "
                         f"{columns[0]}, {columns[1]}")
    return np.array(first), np.array(second), lines


def read_table(path) -> tuple[np.ndarray, np.ndarray]:
    """A PSD table from a CSV file: frequency (Hz), one-sided PSD of acceleration ((m/s^2)^2/Hz).

    The frequencies must be positive and strictly increasing, the PSD values positive (the table
    is interpolated log-log, :class:`~piezo_fmu_harness.excitation.spectra.TablePSD`); at least two rows.
    """
    path = Path(path)
    frequency, density, lines = _parse(path, ("frequency_Hz", "psd_m2_per_s4_per_Hz"))
    table_rows(frequency, density, where=str(path), lines=lines)
    return frequency, density


def table_rows(frequency: np.ndarray, density: np.ndarray, where: str = "the table", lines=None) -> None:
    """Refuse a PSD table that is not positive frequencies, strictly increasing, with positive PSD."""
    line = (lambda k: f", line {lines[k]}") if lines is not None else (lambda k: f", row {k}")
    if frequency.ndim != 1 or frequency.shape != density.shape:
        raise ValueError(f"{where}: frequencies of shape {frequency.shape} and PSD values of shape {density.shape}; "
                         "allowed: two one-dimensional columns of the same length")
    if len(frequency) < 2:
        raise ValueError(f"{where}: {len(frequency)} rows; allowed: at least 2")
    for k in range(len(frequency)):
        f, g = float(frequency[k]), float(density[k])
        if not (math.isfinite(f) and f > 0.0):
            raise ValueError(f"{where}{line(k)}: frequency = {f!r} Hz; allowed range (0, inf) Hz")
        if k and not f > frequency[k - 1]:
            raise ValueError(f"{where}{line(k)}: frequency = {f!r} Hz does not increase; allowed range "
                             f"({frequency[k - 1]:g}, inf) Hz (the frequencies strictly increasing)")
        if not (math.isfinite(g) and g > 0.0):
            raise ValueError(f"{where}{line(k)}: PSD = {g!r} (m/s^2)^2/Hz; allowed range (0, inf) (m/s^2)^2/Hz "
                             "(the table is interpolated log-log)")


#: A recorded step may differ from its first step by this much, relative (the rounding of a CSV's times).
STEP_TOLERANCE = 1e-6


def read_record(path) -> tuple[float, np.ndarray]:
    """A recorded base acceleration from a CSV file: time (s), acceleration (m/s^2).

    The times must increase with a uniform step (every step equal to the first to ``STEP_TOLERANCE``
    relative); they may start anywhere: the record's first row is ``t = 0`` of the excitation.
    Returns ``(step, acceleration)``, the step the mean of the record's (which spares the rounding
    of the file's times).
    """
    path = Path(path)
    time, acceleration, lines = _parse(path, ("time_s", "acceleration_m_per_s2"))
    first = float(time[1] - time[0])
    if not first > 0.0:
        raise ValueError(f"{path}, line {lines[1]}: the times do not increase (from {float(time[0])!r} s to "
                         f"{float(time[1])!r} s); allowed: a uniform, positive step")
    gaps = np.diff(time)
    bad = np.flatnonzero(np.abs(gaps - first) > STEP_TOLERANCE * first)
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"{path}, line {lines[k + 1]}: the step from {float(time[k])!r} s to {float(time[k + 1])!r} s "
                         f"is {float(gaps[k]):g} s; allowed: the record's step {first:g} s (its first), to "
                         f"{STEP_TOLERANCE:g} relative; resample the record to a uniform step first")
    return float((time[-1] - time[0]) / (len(time) - 1)), acceleration
