"""Incremental sweep results: one JSON line per finished point, appended and flushed.

A sweep folder holds ``sweep.json`` (what was asked: axes, fixed values, duration, step, FMU
GUID) and ``points.jsonl`` (what finished). A run killed at any instant leaves at most one
partial last line, which :meth:`PointStore.load` drops; ``--resume`` then runs only the points
that have no complete line, so no finished point is recomputed or lost.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .spec import UsageError, prepare_output_dir

SPEC_FILE = "sweep.json"
POINTS_FILE = "points.jsonl"


class PointStore:
    """The ``points.jsonl`` (or another ``name``) of one results folder."""

    def __init__(self, folder: Path, name: str = POINTS_FILE):
        self.path = Path(folder) / name
        self._handle = None

    def load(self) -> dict[int, dict]:
        """Finished points by index. A partial trailing line (a killed writer) is cut off the
        file; the first record of an index wins should one ever appear twice."""
        if not self.path.is_file():
            return {}
        data = self.path.read_bytes()
        complete = data[: data.rfind(b"\n") + 1]
        if len(complete) != len(data):
            with open(self.path, "r+b") as handle:
                handle.truncate(len(complete))
        records: dict[int, dict] = {}
        for line in complete.splitlines():
            if line.strip():
                record = json.loads(line)
                records.setdefault(int(record["index"]), record)
        return records

    def open(self) -> "PointStore":
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


def open_folder(folder: Path, header_file: str, header: dict, same: tuple, resume: bool, force: bool,
                option: str = "--out", what: str = "run", points_file: str = POINTS_FILE
                ) -> tuple[Path, dict[int, dict], bool]:
    """Check a results folder for the run ``header`` describes and read what it holds; change
    nothing. Returns ``(folder, finished records by index, start_over)``.

    Without ``resume`` a folder that already holds finished points is refused unless ``force``
    (which starts over); with ``resume`` its ``header_file`` must agree with ``header`` on the
    keys ``same`` and on the FMU's GUID. ``what`` names the run in messages. Raises
    :class:`UsageError` naming the option.
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
        if resume:
            if old is None:
                raise UsageError(f"--resume: {path} cannot be read; use --force to start over")
            if json.dumps({k: old.get(k) for k in same}, sort_keys=True) \
                    != json.dumps({k: header.get(k) for k in same}, sort_keys=True):
                raise UsageError(f"--resume: {folder} holds a different {what} (its {header_file} differs in "
                                 f"{', '.join(k for k in same if old.get(k) != header.get(k))}); use the same "
                                 "arguments, or --force to start over")
            if old.get("fmu_guid") != header.get("fmu_guid"):
                raise UsageError(f"--resume: {folder} was run with another FMU (GUID {old.get('fmu_guid')}, "
                                 f"now {header.get('fmu_guid')}); use --force to start over")
            done = store.load()
        elif not force and store.path.is_file() and store.path.stat().st_size > 0:
            count = len(store.load())
            raise UsageError(f"{option} {folder} already holds a {what} ({count} of its points finished); "
                             "pass --resume to finish it, --force to start over, or choose another folder")
    else:
        start_over = True  # points without a header belong to no known run
    return folder, done, start_over
