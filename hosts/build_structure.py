"""Build ``PrimaryStructure.fmu`` (the host model's structure) from ``hosts/primary_structure.py``.

    python hosts/build_structure.py [DEST_DIR]     # default: build/hosts

pythonfmu 0.7.0 writes the archive; the slave is ``primary_structure.py`` (model identifier
``PrimaryStructure``) and the record is ``primary_structure_ground.py``, bundled in
``resources/``. At run time the FMU needs a Python 3 host (no numpy, no scipy).
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SLAVE = HERE / "primary_structure.py"
GROUND = HERE / "primary_structure_ground.py"
DEFAULT_DIR = HERE.parent / "build" / "hosts"
NAME = "PrimaryStructure.fmu"


def build(dest_dir: Path = DEFAULT_DIR, force: bool = False) -> Path:
    """Build the FMU into ``dest_dir`` (skipped when it is newer than its sources) and return it.

    The build runs in a fresh interpreter: a process that has instantiated a pythonfmu FMU may
    import ``pythonfmu`` from that FMU's ``resources/`` (which lacks the binaries), and would
    then write an FMU without ``binaries/``.
    """
    dest_dir = Path(dest_dir)
    target = dest_dir / NAME
    newest_source = max(SLAVE.stat().st_mtime, GROUND.stat().st_mtime)
    if not force and target.is_file() and target.stat().st_mtime >= newest_source and _complete(target):
        return target
    subprocess.run([sys.executable, str(Path(__file__).resolve()), str(dest_dir)], check=True,
                   capture_output=True, text=True)
    if not _complete(target):
        raise RuntimeError(f"{target} was built without its linux64 binary")
    return target


def _complete(fmu: Path) -> bool:
    with zipfile.ZipFile(fmu) as archive:
        names = set(archive.namelist())
    return {"modelDescription.xml", "binaries/linux64/PrimaryStructure.so",
            "resources/primary_structure.py", "resources/primary_structure_ground.py"} <= names


def _build_here(dest_dir: Path) -> Path:
    from pythonfmu import FmuBuilder

    dest_dir.mkdir(parents=True, exist_ok=True)
    return Path(FmuBuilder.build_FMU(SLAVE, dest=dest_dir, project_files=[GROUND]))


if __name__ == "__main__":
    print(_build_here(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_DIR))
