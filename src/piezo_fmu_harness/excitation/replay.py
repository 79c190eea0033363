"""A realization as the rows a host replays: the FMU's inputs at the start of each step.

fmpy's ``simulate_fmu(..., input=rows, output_interval=h)`` with these rows (their times are the
communication points ``k h``, computed as fmpy computes them) sets each row's values before the
step that starts there, so a host needs nothing else to drive the FMU with the realization.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .inputs import whole

#: The columns of a replay: s, m, m/s.
FIELDS = ("time", "base_displacement", "base_velocity")
HEADER = ",".join(FIELDS)


def replay_rows(excitation, realization: int, steps: int) -> np.ndarray:
    """Realization ``realization``'s first ``steps`` steps as a structured array with fields
    ``time`` (``k h``, s), ``base_displacement`` (``y_k``, m) and ``base_velocity`` (``v_k``, m/s),
    one row a step, the values the FMU takes at the step's start."""
    steps = whole("steps", steps, 1)
    y, v = excitation.stream(realization).take(steps)
    rows = np.zeros(steps, dtype=[(name, np.float64) for name in FIELDS])
    rows["time"] = np.arange(steps) * excitation.step
    rows["base_displacement"] = y[:-1]
    rows["base_velocity"] = v
    return rows


def write_replay_csv(path, rows: np.ndarray) -> Path:
    """Write ``rows`` (:func:`replay_rows`) as a CSV with a header line, every value to 17
    significant digits (it reads back to the same bits). Returns the path."""
    path = Path(path)
    table = np.column_stack([rows[name] for name in FIELDS])
    np.savetxt(path, table, delimiter=",", header=HEADER, comments="", fmt="%.17g")
    return path


def read_replay_csv(path) -> np.ndarray:
    """The rows of a CSV written by :func:`write_replay_csv`."""
    path = Path(path)
    with path.open() as handle:
        header = handle.readline().strip()
    if header != HEADER:
        raise ValueError(f"{path}: header {header!r}; allowed: {HEADER!r}")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    rows = np.zeros(len(table), dtype=[(name, np.float64) for name in FIELDS])
    for k, name in enumerate(FIELDS):
        rows[name] = table[:, k]
    return rows
