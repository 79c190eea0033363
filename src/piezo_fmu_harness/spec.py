"""What a run is asked to do, parsed from the command line or a TOML file and checked against
the FMU before anything runs.

Every problem is a :class:`UsageError` whose message names the parameter, the value or the
range at fault; the CLI prints it and exits with status 2.
"""

from __future__ import annotations

import difflib
import itertools
import json
import math
import os
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from .fmu import FmuModel, Parameter

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

#: Default duration of a run (s): the paper does not state its own; docs/model.md section 7.
DEFAULT_STOP_TIME = 2.0
#: Default communication step of a sweep (s). Sweeps keep only end-of-run metrics, which the
#: FMU computes exactly whatever the step (its events are located exactly, and a run chopped
#: into any steps gives the same impacts), so the step only costs time: each step adds about
#: 9 microseconds of FMI and core overhead to a point, whose core now costs about 3.6 ms. 0.2 s
#: (10 steps per 2 s run) keeps a point within about 1.15x the core's own cost in CPU time
#: (0.1 s: 1.2x, 0.02 s: 1.35x, 0.01 s: 1.6x, 1e-3 s: 4.4x); ``--step`` changes it.
DEFAULT_SWEEP_STEP = 0.2


class UsageError(Exception):
    """Bad input: reported before any run, exit status 2."""


@dataclass(frozen=True)
class Axis:
    """One swept parameter and its values (SI), in increasing order."""

    name: str
    values: tuple

    def __len__(self) -> int:
        return len(self.values)


@dataclass(frozen=True)
class SweepSpec:
    """A full-factorial sweep: the axes, the fixed values, the duration and the step (SI)."""

    axes: tuple[Axis, ...]
    fixed: dict = field(default_factory=dict)
    stop_time: float = DEFAULT_STOP_TIME
    step: float = DEFAULT_SWEEP_STEP
    name: str = "sweep"

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(axis) for axis in self.axes)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    def points(self) -> Iterator[tuple[int, dict]]:
        """Every point as ``(index, {axis: value})``, the last axis varying fastest (C order)."""
        names = [axis.name for axis in self.axes]
        for index, combo in enumerate(itertools.product(*(axis.values for axis in self.axes))):
            yield index, dict(zip(names, combo))

    def corners(self) -> Iterator[dict]:
        """The grid's corners: the extreme combinations, checked by the FMU before a run."""
        names = [axis.name for axis in self.axes]
        ends = [sorted({axis.values[0], axis.values[-1]}) for axis in self.axes]
        for combo in itertools.product(*ends):
            yield dict(zip(names, combo))

    def values_at(self, point: dict) -> dict:
        """The FMU parameter values of one point: the fixed values and the point's."""
        return {**self.fixed, **point}

    def to_dict(self) -> dict:
        return {"name": self.name, "axes": {axis.name: list(axis.values) for axis in self.axes},
                "fixed": dict(self.fixed), "stop_time": self.stop_time, "step": self.step}

    def fingerprint(self) -> str:
        """What must match for a resumed sweep to be the same sweep (JSON text)."""
        body = self.to_dict()
        body.pop("name")
        return json.dumps(body, sort_keys=True)


# -- parsing ---------------------------------------------------------------------------------------

def _lookup(model: FmuModel, name: str, where: str) -> Parameter:
    if name in model.parameters:
        return model.parameters[name]
    close = difflib.get_close_matches(name, model.parameters, n=3)
    hint = f" Did you mean {' or '.join(close)}?" if close else ""
    kind = " (an output, not a parameter)" if name in model.outputs else ""
    raise UsageError(f"unknown parameter {name!r}{kind} in {where}.{hint} "
                     f"The FMU's parameters are: {', '.join(model.parameters)}")


def _split(text: str, what: str, form: str) -> tuple[str, str]:
    name, sep, rest = text.partition("=")
    name = name.strip()
    if not sep or not name or not rest.strip():
        raise UsageError(f"{what} {text!r}: expected {form}")
    return name, rest.strip()


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text!r} is not finite")
    return value


def _checked(parameter: Parameter, value, where: str):
    try:
        return parameter.coerce(value)
    except ValueError as error:
        raise UsageError(f"{where}: {error}") from None


def parse_assignment(model: FmuModel, text: str) -> tuple[str, float | int]:
    """``NAME=VALUE`` (SI) into a checked ``(name, value)``."""
    name, value_text = _split(text, "--set", "NAME=VALUE")
    where = f"--set {text}"
    parameter = _lookup(model, name, where)
    return name, _checked(parameter, _number(value_text, where), where)


def make_axis(model: FmuModel, name: str, start: float, stop: float, count, where: str) -> Axis:
    """The axis ``linspace(start, stop, count)`` of parameter ``name``, checked.

    ``count`` >= 1; ``start < stop`` when ``count > 1`` and ``start == stop`` when it is 1; every
    value within the modelDescription's bounds.
    """
    parameter = _lookup(model, name, where)
    if isinstance(count, float) and count.is_integer():
        count = int(count)
    if not isinstance(count, int) or isinstance(count, bool):
        raise UsageError(f"{where}: COUNT = {count!r} is not a whole number of points")
    if count < 1:
        raise UsageError(f"{where}: empty range for {name}: COUNT = {count} (need at least 1 point; "
                         "allowed range [1, inf))")
    if count > 1 and start == stop:
        raise UsageError(f"{where}: empty range for {name}: START = STOP = {start:g} with COUNT = {count} "
                         "(use COUNT = 1 for a single value, or --set)")
    if start > stop:
        raise UsageError(f"{where}: reversed range for {name}: START = {start:g} is above STOP = {stop:g} "
                         "(give START < STOP)")
    if count == 1 and start != stop:
        raise UsageError(f"{where}: range {start:g}:{stop:g} of {name} has COUNT = 1 (need COUNT >= 2, "
                         "or START = STOP)")
    values = np.linspace(start, stop, count) if count > 1 else np.array([start])
    # 15 significant digits drop linspace's rounding noise (0.009000000000000001 -> 0.009).
    checked = tuple(_checked(parameter, float(f"{v:.15g}"), where) for v in values)
    if parameter.type == "Integer" and len(set(checked)) != len(checked):
        raise UsageError(f"{where}: {name} is an Integer parameter; {start:g}:{stop:g}:{count} does not "
                         "give distinct whole numbers")
    return Axis(name, checked)


def parse_grid(model: FmuModel, text: str) -> Axis:
    """``NAME=START:STOP:COUNT`` (SI) into a checked :class:`Axis`."""
    name, rest = _split(text, "--grid", "NAME=START:STOP:COUNT")
    where = f"--grid {text}"
    parts = rest.split(":")
    if len(parts) != 3:
        raise UsageError(f"{where}: expected NAME=START:STOP:COUNT, e.g. x1=0:0.03:31")
    start, stop = _number(parts[0], where), _number(parts[1], where)
    try:
        count = int(parts[2])
    except ValueError:
        raise UsageError(f"{where}: COUNT = {parts[2]!r} is not a whole number of points") from None
    return make_axis(model, name, start, stop, count, where)


def axis_from_values(model: FmuModel, name: str, values, where: str) -> Axis:
    """An axis from an explicit list (TOML), strictly increasing, within bounds."""
    parameter = _lookup(model, name, where)
    if not isinstance(values, list) or not values:
        raise UsageError(f"{where}: empty list of values for {name}")
    numbers = [_number(str(v), where) for v in values]
    if any(b <= a for a, b in zip(numbers, numbers[1:])):
        raise UsageError(f"{where}: the values of {name} must be strictly increasing, got {values}")
    return Axis(name, tuple(_checked(parameter, v, where) for v in numbers))


def load_toml(model: FmuModel, path: Path) -> dict:
    """A sweep file: ``stop_time``, ``step``, ``out``, ``[grid]`` and ``[set]`` tables.

    ``[grid]`` values are ``"START:STOP:COUNT"``, ``{start, stop, count}`` or a list of values.
    Returns ``{"axes": [...], "fixed": {...}, "stop_time": ..., "step": ..., "out": ...}`` with
    the keys present in the file.
    """
    where = f"sweep file {path}"
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise UsageError(f"{where} does not exist") from None
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise UsageError(f"{where} cannot be read: {error}") from None
    known = {"grid", "set", "stop_time", "step", "out", "name"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise UsageError(f"{where}: unknown keys {unknown}; allowed: {sorted(known)}")
    result: dict = {"axes": [], "fixed": {}}
    for name, value in data.get("grid", {}).items():
        at = f"{where} [grid] {name}"
        if isinstance(value, str):
            result["axes"].append(parse_grid(model, f"{name}={value}"))
        elif isinstance(value, dict):
            missing = {"start", "stop", "count"} - set(value)
            if missing:
                raise UsageError(f"{at}: missing {sorted(missing)}")
            result["axes"].append(make_axis(model, name, _number(str(value["start"]), at),
                                            _number(str(value["stop"]), at), value["count"], at))
        else:
            result["axes"].append(axis_from_values(model, name, value, at))
    for name, value in data.get("set", {}).items():
        at = f"{where} [set] {name}"
        result["fixed"][name] = _checked(_lookup(model, name, at), _number(str(value), at), at)
    for key in ("stop_time", "step"):
        if key in data:
            result[key] = _number(str(data[key]), f"{where} {key}")
    for key in ("out", "name"):
        if key in data:
            result[key] = str(data[key])
    return result


def check_times(stop_time: float, step: float) -> None:
    """A positive, finite duration and communication step, the step no longer than the run."""
    if not (math.isfinite(stop_time) and stop_time > 0):
        raise UsageError(f"--stop-time {stop_time:g}: the duration must be a finite number of seconds > 0; "
                         "allowed range (0, inf) s")
    if not (math.isfinite(step) and step > 0):
        raise UsageError(f"--step {step:g}: the communication step must be a finite number of "
                         "seconds > 0; allowed range (0, inf) s")
    if step > stop_time:
        raise UsageError(f"--step {step:g} is longer than --stop-time {stop_time:g}")


def build_spec(axes: list[Axis], fixed: dict, stop_time: float, step: float, name: str) -> SweepSpec:
    """A :class:`SweepSpec` after the checks that need all the pieces together."""
    if not axes:
        raise UsageError("no grid: give --grid NAME=START:STOP:COUNT, --preset NAME or --config FILE")
    names = [axis.name for axis in axes]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"parameter {repeated[0]!r} is given more than one grid")
    both = sorted(set(names) & set(fixed))
    if both:
        raise UsageError(f"parameter {both[0]!r} is both swept (--grid) and fixed (--set); give one")
    check_times(stop_time, step)
    return SweepSpec(axes=tuple(axes), fixed=dict(fixed), stop_time=stop_time, step=step, name=name)


def check_with_fmu(model: FmuModel, instance, values_list: list[dict], where: str) -> None:
    """Let the FMU itself accept each set of values (its cross-checks, e.g. ``x1 + L_p <= L``
    or ``M > M_eq``, are not expressible as min/max). One tiny step each; no result kept."""
    from .fmu import FmuRunError

    for values in values_list:
        try:
            instance.run(values, stop_time=1e-9, step=1e-9)
        except FmuRunError as error:
            shown = ", ".join(f"{k} = {v:g}" for k, v in values.items())
            raise UsageError(f"{where}: the FMU rejects {shown or 'its defaults'}: {error}") from None


# -- output folders --------------------------------------------------------------------------------

def prepare_output_dir(path: Path, option: str = "--out") -> Path:
    """Create ``path`` if needed and prove it writable, or raise :class:`UsageError`."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".write-test-"):
            pass
    except OSError as error:
        reason = error.strerror or str(error)
        raise UsageError(f"{option} {path}: output folder is not writable ({reason})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: output folder is not writable")
    return path
