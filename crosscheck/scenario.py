"""The cross-check scenario of ``fmus/PiezoImpactDamper.fmu`` and its files, read and written.

The scenario: harmonic base excitation near resonance, started from rest.

- Start values: ``p0 = q0 = 0`` (both masses at rest at the origin; ``dp0 = dq0 = 0`` by
  default); every other parameter keeps the FMU's default (Table 1 of the paper, ``M = 1 kg``,
  ``K = 1000 N/m``, ``C = 0.1 N s/m``, ``m = 0.1 kg``, ``d = 8 mm``, ``R_load = 52 kOhm``).
- Inputs: ``base_displacement = Y sin(w t)``, ``base_velocity = Y w cos(w t)`` with
  ``Y = 1 mm`` and ``w = 31.6 rad/s`` (5.03 Hz; the main mass's own frequency is
  ``sqrt(K/M) = 31.62 rad/s``), sampled at ``t_k = k * 1 ms``, ``k = 0 .. 1000``, and written
  with round-trip precision. Between two samples the FMU moves the base as
  ``y = y_k + v_k (t - t_k)`` (its input hold), so the sampled pair fully defines the run.
- Grid: 0 to 1 s at a 1 ms communication step. The grid is the one of the FMI cross-check's
  ``StepSize`` counted in whole nanoseconds: ``t_k`` is the double nearest to ``k * 1e-3``
  (``(k * 10**6) / 1e9``, correctly rounded), the step passed to ``fmi2DoStep`` is
  ``t_{k+1} - t_k``. OSP libcosim counts time this way; the project's fmpy driver and C host
  do the same.

Files (layout of the FMI cross-check rules, modelica/fmi-cross-check):
``PiezoImpactDamper_in.csv`` (inputs), ``PiezoImpactDamper_ref.csv`` (reference result, every
output of the FMU), ``PiezoImpactDamper_ref.opt`` (start, stop, step, tolerance) and
``ReadMe.md``. ``python crosscheck/run_crosscheck.py --write`` rewrites the input and the
reference (the reference with the fmpy driver).

Comparison (``compare``): on the same grid (times equal within ``1e-12 * max(1, |t|)`` s),
every Real output ``x`` must satisfy ``|x - x_ref| <= RelTol * (|x_ref| + S)`` at every point,
where ``S`` is the peak of ``|x_ref|`` over the run (so that the band does not collapse where a
signal crosses zero) and ``RelTol = 1e-10`` from the ``.opt`` file; ``energy_balance_error``,
a residual that is zero up to rounding, takes as ``S`` the peak of ``energy_dissipated`` (the
size of the ledger it closes). ``impact_count`` (Integer) must be equal.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
MODEL_NAME = "PiezoImpactDamper"
FMU_PATH = REPO / "fmus" / f"{MODEL_NAME}.fmu"
#: The same model as an FMI 3.0 FMU: the same bits in co-simulation.
FMU3_PATH = REPO / "fmus" / f"{MODEL_NAME}3.fmu"
IN_CSV = HERE / f"{MODEL_NAME}_in.csv"
REF_CSV = HERE / f"{MODEL_NAME}_ref.csv"
REF_OPT = HERE / f"{MODEL_NAME}_ref.opt"

#: Base excitation: amplitude (m) and circular frequency (rad/s).
AMPLITUDE = 1e-3
OMEGA = 31.6
START_TIME = 0.0
#: 1 s: the last second within which the reference holds on any machine. The impacts amplify a
#: last-bit difference about tenfold per 0.1 s; other BLAS kernels and SIMD levels (another CPU
#: family) change last bits, which grow to ~1e-11 of each output's peak by 1 s, 2e-10 by 2 s and
#: 2e-5 by 3 s (tests/test_crosstool.py runs the reference under other kernels).
STOP_TIME = 1.0
STEP_SIZE = 1e-3
REL_TOL = 1e-10
#: Start values the importer must set (everything else keeps the FMU's defaults).
START_VALUES = {"p0": 0.0, "q0": 0.0}
INPUTS = ("base_displacement", "base_velocity")
#: Times of two grids are the same point when they differ by at most this, relative.
TIME_RTOL = 1e-12
#: The signal whose peak scales the band of each residual-like output.
SCALE_OF = {"energy_balance_error": "energy_dissipated"}


def step_ns(step: float = STEP_SIZE) -> int:
    """The communication step in whole nanoseconds."""
    return int(round(step * 1e9))


def grid(start: float = START_TIME, stop: float = STOP_TIME, step: float = STEP_SIZE) -> np.ndarray:
    """The communication points ``t_k`` (s): the doubles nearest to ``start + k * step``."""
    start_ns, dt_ns = int(round(start * 1e9)), step_ns(step)
    n = int(round((stop - start) * 1e9)) // dt_ns
    return np.array([(start_ns + k * dt_ns) / 1e9 for k in range(n + 1)])


def accumulated_grid(start: float = START_TIME, stop: float = STOP_TIME, step: float = STEP_SIZE) -> np.ndarray:
    """The points of a master that adds the step to its time at every step (ecos does)."""
    n = int(round((stop - start) * 1e9)) // step_ns(step)
    times = [start]
    for _ in range(n):
        times.append(times[-1] + step)
    return np.array(times)


def multiplied_grid(start: float = START_TIME, stop: float = STOP_TIME, step: float = STEP_SIZE) -> np.ndarray:
    """The points of a master that computes ``start + k * step`` (fmpy's ``simulate_fmu`` does)."""
    n = int(round((stop - start) * 1e9)) // step_ns(step)
    return np.array([start + k * step for k in range(n + 1)])


def base_motion(t: float) -> tuple[float, float]:
    """``(y, v_b)`` of the harmonic base excitation at time ``t``."""
    return AMPLITUDE * math.sin(OMEGA * t), AMPLITUDE * OMEGA * math.cos(OMEGA * t)


# -- CSV files (FMI cross-check format) ------------------------------------------------------------

def _fmt(value) -> str:
    """A number as the shortest literal that reads back to the same double (C syntax)."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return repr(float(value))


def write_csv(path: Path, time: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    """Write ``"time"`` and the columns: quoted names, comma-separated, round-trip numbers."""
    names = list(columns)
    with open(path, "w", newline="\n") as f:
        f.write(",".join(f'"{n}"' for n in ["time"] + names) + "\n")
        for k, t in enumerate(time):
            f.write(",".join([_fmt(t)] + [_fmt(columns[n][k]) for n in names]) + "\n")


def read_csv(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(time, {name: values})`` of a cross-check CSV; integer-valued columns stay integers."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    names = [n.strip().strip('"') for n in rows[0]]
    if names[0] != "time":
        raise ValueError(f"{path}: the first column must be time, not {names[0]!r}")
    data = rows[1:]
    columns = {}
    for j, name in enumerate(names):
        texts = [r[j].strip() for r in data]
        if all(_is_int(s) for s in texts) and name != "time":
            columns[name] = np.array([int(s) for s in texts], dtype=np.int64)
        else:
            columns[name] = np.array([float(s) for s in texts])
    time = columns.pop("time")
    return time, columns


def _is_int(text: str) -> bool:
    return text.lstrip("-").isdigit()


def input_table() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The inputs sampled on the grid (what ``PiezoImpactDamper_in.csv`` holds)."""
    time = grid()
    samples = [base_motion(float(t)) for t in time]
    return time, {"base_displacement": np.array([s[0] for s in samples]),
                  "base_velocity": np.array([s[1] for s in samples])}


def write_inputs(path: Path = IN_CSV) -> None:
    time, columns = input_table()
    write_csv(path, time, columns)


def read_opt(path: Path = REF_OPT) -> dict[str, float]:
    """The ``.opt`` file: ``Key,value`` lines."""
    options = {}
    for line in Path(path).read_text().splitlines():
        if line.strip():
            key, value = (s.strip() for s in line.split(",", 1))
            options[key] = float(value)
    return options


def write_opt(path: Path = REF_OPT) -> None:
    Path(path).write_text(
        f"StartTime,{START_TIME!r}\nStopTime,{STOP_TIME!r}\nStepSize,{STEP_SIZE!r}\n"
        f"RelTol,{REL_TOL!r}\nOutputIntervalLength,{STEP_SIZE!r}\n")


# -- comparison --------------------------------------------------------------------------------------

@dataclass
class Comparison:
    """Per-variable worst relative deviation (deviation / band width * RelTol) and the verdict."""

    rel_tol: float
    worst: dict[str, float] = field(default_factory=dict)  # max |x - x_ref| / (|x_ref| + S)
    worst_at: dict[str, float] = field(default_factory=dict)  # time of that maximum
    bit_identical: dict[str, bool] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.problems

    @property
    def max_relative(self) -> float:
        return max(self.worst.values(), default=0.0)

    @property
    def all_bit_identical(self) -> bool:
        return all(self.bit_identical.values())

    def report(self) -> str:
        lines = [f"{'variable':24s} {'max rel. dev.':>14s} {'at t (s)':>9s}  bit-identical"]
        for name in self.worst:
            lines.append(f"{name:24s} {self.worst[name]:14.3e} {self.worst_at[name]:9.3f}  "
                         f"{'yes' if self.bit_identical[name] else 'no'}")
        return "\n".join(lines)


def compare(time: np.ndarray, outputs: dict[str, np.ndarray], ref_time: np.ndarray,
            ref: dict[str, np.ndarray], rel_tol: float = REL_TOL) -> Comparison:
    """Compare a result with a reference on the same grid (see the module docstring)."""
    result = Comparison(rel_tol=rel_tol)
    time = np.asarray(time, dtype=float)
    if len(time) != len(ref_time):
        result.problems.append(f"{len(time)} output points, the reference has {len(ref_time)}")
        return result
    dt = np.abs(time - ref_time)
    if np.any(dt > TIME_RTOL * np.maximum(1.0, np.abs(ref_time))):
        k = int(np.argmax(dt))
        result.problems.append(f"time grid differs: t = {time[k]!r} against {ref_time[k]!r}")
    for name, expected in ref.items():
        if name not in outputs:
            result.problems.append(f"{name} missing from the result")
            continue
        actual = np.asarray(outputs[name])
        if expected.dtype.kind in "iu":
            result.bit_identical[name] = bool(np.array_equal(actual, expected))
        else:  # the bits: tells -0.0 from 0.0
            result.bit_identical[name] = bool(np.array_equal(
                np.ascontiguousarray(actual, dtype=float).view(np.int64), expected.view(np.int64)))
        if expected.dtype.kind in "iu":
            wrong = np.nonzero(actual != expected)[0]
            result.worst[name] = 0.0 if len(wrong) == 0 else math.inf
            result.worst_at[name] = float(ref_time[wrong[0]]) if len(wrong) else 0.0
            if len(wrong):
                result.problems.append(f"{name}: {actual[wrong[0]]} != {expected[wrong[0]]} at t = {ref_time[wrong[0]]}")
            continue
        scale = float(np.max(np.abs(ref[SCALE_OF.get(name, name)])))
        band = np.abs(expected) + scale
        band = np.where(band > 0.0, band, 1.0)  # an all-zero reference: compare absolutely
        rel = np.abs(actual.astype(float) - expected) / band
        if not np.all(np.isfinite(rel)):
            result.problems.append(f"{name}: non-finite values")
            rel = np.where(np.isfinite(rel), rel, math.inf)
        k = int(np.argmax(rel))
        result.worst[name], result.worst_at[name] = float(rel[k]), float(ref_time[k])
        if rel[k] > rel_tol:
            result.problems.append(f"{name}: relative deviation {rel[k]:.3e} > {rel_tol:g} at t = {ref_time[k]:.3f} s")
    return result


def read_reference() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    return read_csv(REF_CSV)


def read_inputs(path: Optional[Path] = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    return read_csv(IN_CSV if path is None else path)
