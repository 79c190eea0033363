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

SPEC_FILE = "sweep.json"
POINTS_FILE = "points.jsonl"


class PointStore:
    """The ``points.jsonl`` of one sweep folder."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / POINTS_FILE
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
