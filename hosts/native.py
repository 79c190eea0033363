"""Build and run the project's C host (``hosts/native_host.c``) under its launcher.

The host is compiled with the system C compiler (``cc``, or ``$CC``) against the FMI 2.0 headers
that fmpy ships (``fmpy/c-code``: ``fmi2FunctionTypes.h`` and ``fmi2TypesPlatform.h``, the
standard's BSD-licensed headers), and run through ``hosts/run_native_host.sh``, which puts
libpython into the process (see that script). The FMU archive is extracted to a scratch folder
for the run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Optional, Sequence

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "native_host.c"
LAUNCHER = HERE / "run_native_host.sh"
BUILD_DIR = HERE.parent / "build" / "hosts"


def fmi_headers() -> Path:
    """The folder with fmpy's copy of the FMI 2.0 headers."""
    import fmpy

    folder = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (folder / "fmi2FunctionTypes.h").is_file():
        raise FileNotFoundError(f"no FMI 2.0 headers in {folder}")
    return folder


def compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise FileNotFoundError("no C compiler: install one (Debian: apt-get install gcc)")
    return cc


def build(dest: Optional[Path] = None) -> Path:
    """Compile the host (warnings are errors) and return the executable's path."""
    dest = Path(dest) if dest is not None else BUILD_DIR / "native_host"
    dest.parent.mkdir(parents=True, exist_ok=True)
    if dest.is_file() and dest.stat().st_mtime >= SOURCE.stat().st_mtime:
        return dest
    command = [compiler(), "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-I", str(fmi_headers()),
               str(SOURCE), "-o", str(dest), "-ldl", "-lm"]
    subprocess.run(command, check=True, capture_output=True, text=True)
    return dest


def environment(python: Optional[str] = None) -> dict[str, str]:
    """The process environment with ``PYTHON`` set for the launcher."""
    env = dict(os.environ)
    env["PYTHON"] = python or sys.executable
    return env


def run(fmu: Path, out_csv: Path, args: Sequence[str] = (), python: Optional[str] = None,
        executable: Optional[Path] = None, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """Run the host on ``fmu`` (extracted to a scratch folder) under the launcher.

    Raises ``subprocess.CalledProcessError`` on a non-zero exit; the completed process (with its
    stdout and stderr) is returned otherwise.
    """
    executable = Path(executable) if executable is not None else build()
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_native_") as scratch:
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(scratch)
        command = ["sh", str(LAUNCHER), str(executable), scratch, str(out_csv), *args]
        completed = subprocess.run(command, env=environment(python), capture_output=True, text=True,
                                   timeout=timeout)
    if completed.returncode != 0:
        raise subprocess.CalledProcessError(completed.returncode, command, completed.stdout, completed.stderr)
    return completed
