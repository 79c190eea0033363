"""Incremental sweep results: one JSON line per finished point, appended and flushed.

A sweep folder holds ``sweep.json`` (what was asked: axes, fixed values, duration, step, FMU
GUID) and ``points.jsonl`` (what finished). A run killed at any instant leaves at most one
partial last line, which :meth:`PointStore.load` passes over and :meth:`PointStore.open` cuts off
before it appends; ``--resume`` then runs only the points that have no complete line, so no
finished point is recomputed or lost.

Any other line that is not a record of the run (not JSON, not an object, without the fields the
study reads, or of another run: each study's check says) stops the run before anything is
written, naming the file and the line: nothing recorded is lost or overwritten.

**The rule of a results folder**, every command's: a folder that holds another run is refused
unless ``--force``, which replaces it. A long command records as it goes and checks its folder with
:func:`open_folder` (``--resume`` finishes the run it holds); a short one writes at its end and
checks it with :func:`claim_folder`.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from .spec import UsageError, prepare_output_dir

SPEC_FILE = "sweep.json"
POINTS_FILE = "points.jsonl"
#: What a damaged points file tells the user to do.
REMEDY = ("nothing was changed; mend or delete that line to resume, or use --force to start over (it discards "
          "the recorded points)")


class Damaged(ValueError):
    """What is wrong with one record of a points file: raised by a study's check of its records."""


#: How a message names each kind of a record's field (``int`` a whole number, ``float`` any number).
KINDS = {int: "a whole number", float: "a number", str: "text", list: "a list", dict: "an object",
         type(None): "null"}


def _is(value, kind) -> bool:
    if isinstance(kind, tuple):
        return any(_is(value, one) for one in kind)
    if isinstance(value, bool):
        return False  # JSON's true and false are no numbers here
    return isinstance(value, (int, float) if kind is float else kind)


def _kind(kind) -> str:
    return " or ".join(KINDS[one] for one in kind) if isinstance(kind, tuple) else KINDS[kind]


def _shown(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def require(record: dict, fields: dict, where: str = "", optional: bool = False) -> None:
    """Raise :class:`Damaged` unless ``record`` holds each of ``fields`` (name: ``int``, ``float``,
    ``str``, ``list``, ``dict``, or a tuple of them with ``type(None)`` for null) of its kind.
    ``optional``: a field may be absent, but one present must be of its kind. ``where`` heads the
    message (``"start 3's "``)."""
    for key, kind in fields.items():
        if key not in record:
            if optional:
                continue
            raise Damaged(f"{where}{key!r} is missing")
        if not _is(record[key], kind):
            raise Damaged(f"{where}{key!r} is {_shown(record[key])}, not {_kind(kind)}")


def numbers(record: dict, keys, where: str = "") -> None:
    """Each of ``keys`` that ``record`` holds is a number or null."""
    require(record, dict.fromkeys(keys, (float, type(None))), where, optional=True)


def vector(record: dict, key: str, length: int) -> None:
    """``record[key]`` is a list of ``length`` numbers."""
    require(record, {key: list})
    if len(record[key]) != length or not all(_is(v, float) for v in record[key]):
        raise Damaged(f"{key!r} is {_shown(record[key])}, not a list of {length} number{'s' * (length != 1)}")


def within(index: int, count: int, what: str = "point") -> None:
    """``index`` is one of this run's ``count``."""
    if not 0 <= index < count:
        raise Damaged(f"{what} {index} is outside this run (its {what}s are 0 to {count - 1}): a record of another "
                      "run")


class PointStore:
    """The ``points.jsonl`` (or another ``name``) of one results folder."""

    def __init__(self, folder: Path, name: str = POINTS_FILE):
        self.path = Path(folder) / name
        self._handle = None

    def load(self, check: Optional[Callable[[dict], None]] = None) -> dict[int, dict]:
        """Finished points by index; the first record of an index wins should one ever appear
        twice. A partial trailing line (a killed writer) is passed over (:meth:`open` cuts it
        off). Every complete line must be a JSON object with a whole ``index`` that passes
        ``check`` (a study's: it raises :class:`Damaged`); else a :class:`UsageError` names the
        line, and the file is left as it is. Changes nothing."""
        if not self.path.exists():
            return {}
        try:
            data = self.path.read_bytes()
        except OSError as error:
            raise UsageError(f"{self.path} cannot be read ({error.strerror or error}); use --force to start over "
                             "(it discards the recorded points)") from None
        records: dict[int, dict] = {}
        for number, line in enumerate(data[: data.rfind(b"\n") + 1].split(b"\n")[:-1], 1):
            if not line.strip():
                continue
            try:
                record = _record(line, check)
            except Damaged as error:
                raise UsageError(f"{self.path}: line {number}: {error}; {REMEDY}") from None
            records.setdefault(record["index"], record)
        return records

    def open(self) -> "PointStore":
        """Open for appending, first cutting off a partial last line (a killed writer's), so that
        the next record starts a line of its own."""
        if self.path.is_file() and self.path.stat().st_size:
            with open(self.path, "r+b") as handle:
                handle.seek(-1, os.SEEK_END)
                if handle.read(1) != b"\n":
                    handle.seek(0)
                    handle.truncate(handle.read().rfind(b"\n") + 1)
        self._handle = open(self.path, "a", encoding="utf-8")
        return self

    def append(self, record: dict) -> None:
        """Write one record as one line and flush it to the operating system at once."""
        self._handle.write(json.dumps(record, allow_nan=False) + "\n")
        self._handle.flush()

    def close(self) -> None:
        if self._handle is not None:
            self._handle.flush()
            os.fsync(self._handle.fileno())
            self._handle.close()
            self._handle = None

    def __enter__(self) -> "PointStore":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def clear(self) -> None:
        if self.path.exists():
            self.path.unlink()


def jsonable(value):
    """``value`` with every number that is not finite as null: JSON has no NaN, and a record or a
    summary is written strictly (numpy's scalars as Python's numbers)."""
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, dict):
        return {key: jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    return value


def write_json(path: Path, data) -> None:
    """``data`` as strict JSON, indented (what is not finite as null, see :func:`jsonable`): a
    study's summary that any JSON reader takes."""
    path.write_text(json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")


def _record(line: bytes, check: Optional[Callable[[dict], None]]) -> dict:
    """One line of a points file as a record, or :class:`Damaged` saying why it is none."""
    try:
        record = json.loads(line)
    except json.JSONDecodeError as error:
        raise Damaged(f"not JSON ({error.msg} at column {error.colno})") from None
    except (ValueError, RecursionError):  # not UTF-8 text, or nested beyond Python's stack
        raise Damaged("not JSON text") from None
    if not isinstance(record, dict):
        raise Damaged(f"{_shown(record)} is not a record (a JSON object)")
    require(record, {"index": int})
    if check is not None:
        check(record)
    return record


def open_folder(folder: Path, header_file: str, header: dict, same: tuple, resume: bool, force: bool,
                option: str = "--out", what: str = "run", points_file: str = POINTS_FILE,
                check: Optional[Callable[[dict], None]] = None) -> tuple[Path, dict[int, dict], bool]:
    """Check a results folder for the run ``header`` describes and read what it holds; change
    nothing. Returns ``(folder, finished records by index, start_over)``.

    Without ``resume`` a folder that already holds points is refused unless ``force`` (which
    starts over); with ``resume`` its ``header_file`` must agree with ``header`` on the keys
    ``same`` and on the FMU's GUID, and every record must pass ``check`` (see
    :meth:`PointStore.load`). A folder without a header starts afresh, unless it holds points:
    no run is known to own them, so only ``force`` discards them. ``what`` names the run in
    messages. Raises :class:`UsageError` naming the option or the file.
    """
    folder = prepare_output_dir(folder, option)
    path = folder / header_file
    store = PointStore(folder, points_file)
    done: dict = {}
    start_over = force
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            old = None
        old = old if isinstance(old, dict) else None  # JSON, but no header
        if resume:
            if old is None:
                raise UsageError(f"--resume: {path} cannot be read as a {what}'s header; nothing was changed; use "
                                 "--force to start over (it discards the recorded points)")
            if json.dumps({k: old.get(k) for k in same}, sort_keys=True) \
                    != json.dumps({k: header.get(k) for k in same}, sort_keys=True):
                raise UsageError(f"--resume: {folder} holds a different {what} (its {header_file} differs in "
                                 f"{', '.join(k for k in same if old.get(k) != header.get(k))}); use the same "
                                 "arguments, or --force to start over")
            if old.get("fmu_guid") != header.get("fmu_guid"):
                raise UsageError(f"--resume: {folder} was run with another FMU (GUID {old.get('fmu_guid')}, "
                                 f"now {header.get('fmu_guid')}); use --force to start over")
            done = store.load(check)
        elif not force and store.path.is_file() and store.path.stat().st_size > 0:
            count = len(store.load(check))
            raise UsageError(f"{option} {folder} already holds a {what} ({count} of its points finished); "
                             "pass --resume to finish it, --force to start over, or choose another folder")
    elif not force and store.path.exists() and (not store.path.is_file() or store.path.stat().st_size > 0):
        raise UsageError(f"{'--resume:' if resume else option} {folder} holds {store.path.name} but no {header_file}, "
                         f"so no {what} is known to own its points; nothing was changed; use --force to start over (it "
                         "discards the recorded points), or choose another folder")
    else:
        start_over = True  # no header: a fresh run
    return folder, done, start_over


def claim_folder(folder: Path, written: tuple, force: bool, what: str, option: str = "--out") -> Path:
    """The results folder of a command that writes its results at its end (no ``--resume``):
    created and proven writable; a folder that holds any file the command writes (the names or
    glob patterns ``written``) holds another run, refused unless ``force``, which removes those
    files. ``what`` names the run in the message. Raises :class:`UsageError` naming the option."""
    folder = prepare_output_dir(folder, option)
    held = sorted({path for pattern in written for path in folder.glob(pattern) if path.is_file()})
    if held and not force:
        shown = ", ".join(path.name for path in held[:3]) + (f" and {len(held) - 3} more" if len(held) > 3 else "")
        raise UsageError(f"{option} {folder} already holds a {what} ({shown}); nothing was changed; pass --force to "
                         "replace it, or choose another folder")
    for path in held:
        path.unlink()
    return folder
