"""Build and run the project's C host (``hosts/native_host.c``) as a user's native tool runs.

The host is compiled with the system C compiler (``cc``, or ``$CC``) against the FMI 2.0 and
3.0 headers that fmpy ships (``fmpy/c-code``, the standard's BSD-licensed headers), and run in a
bare environment: nothing but ``PATH``, which holds the Python with numpy that the FMU's loader
is to find (``python3`` in the folder of the given interpreter, a virtual environment's
``bin``). No ``LD_PRELOAD``, ``PYTHONHOME`` or ``PYTHONPATH``: the FMU finds Python itself. The
FMU archive is extracted to a scratch folder for the run. ``hosts/run_native_host.sh`` remains
for those who prefer to put libpython into a host themselves.

:func:`build_windows` cross-compiles the same host for Windows with mingw-w64; the Windows tests
(``tests/test_windows.py``, ``tests/windows.py``) run it under Wine.

It imports nothing of ``piezo_fmu``: a process that has run an FMU may hold the FMU's bundled copy
of the package under that name.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Mapping, Optional, Sequence

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "native_host.c"
LAUNCHER = HERE / "run_native_host.sh"
BUILD_DIR = HERE.parent / "build" / "hosts"
#: The system's folders that a bare environment's PATH keeps after the chosen Python's.
SYSTEM_PATH = "/usr/bin:/bin"
#: Variables a bare environment keeps from this process: they choose numpy's and OpenBLAS's
#: kernels (``OPENBLAS_CORETYPE``, ...), which decide the last bits of the core's products, so
#: that the host computes with the same kernels as a Python importer in this process.
KERNEL_PREFIXES = ("OPENBLAS_", "NPY_")


def fmi_headers() -> Path:
    """The folder with fmpy's copy of the FMI 2.0 and 3.0 headers."""
    import fmpy

    folder = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (folder / "fmi3FunctionTypes.h").is_file():
        raise FileNotFoundError(f"no FMI headers in {folder}")
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
               str(SOURCE), "-o", str(dest), "-ldl", "-lm", "-lpthread"]
    subprocess.run(command, check=True, capture_output=True, text=True)
    return dest


def build_windows(dest: Optional[Path] = None) -> Path:
    """The host for Windows, cross-compiled with mingw-w64 (static: it needs no DLL of mingw's;
    mingw's own printf and strtod, correctly rounded as glibc's are)."""
    dest = Path(dest) if dest is not None else BUILD_DIR / "native_host.exe"
    dest.parent.mkdir(parents=True, exist_ok=True)
    if dest.is_file() and dest.stat().st_mtime >= SOURCE.stat().st_mtime:
        return dest
    mingw = shutil.which("x86_64-w64-mingw32-gcc")
    if not mingw:
        raise FileNotFoundError("no x86_64-w64-mingw32-gcc: `make system-deps` installs it "
                                "(Debian: apt-get install gcc-mingw-w64-x86-64)")
    command = [mingw, "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-D__USE_MINGW_ANSI_STDIO=1",
               "-I", str(fmi_headers()), str(SOURCE), "-o", str(dest), "-static"]
    subprocess.run(command, check=True, capture_output=True, text=True)
    return dest


def environment(python: Optional[str] = None, extra: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """A bare environment whose ``PATH`` finds ``python3`` = ``python`` (default: this interpreter).

    It has the numerical-kernel settings of this process (``KERNEL_PREFIXES``) and ``extra``
    (``PIEZO_FMU_PYTHON``, for example), and nothing else.
    """
    folder = Path(python or sys.executable).absolute().parent
    if not os.access(folder / "python3", os.X_OK):
        raise FileNotFoundError(f"no python3 in {folder}: give the interpreter of a virtual environment")
    kernels = {key: value for key, value in os.environ.items() if key.startswith(KERNEL_PREFIXES)}
    return {**kernels, "PATH": f"{folder}:{SYSTEM_PATH}", **(extra or {})}


def run(fmu: Path, out_csv: Path, args: Sequence[str] = (), python: Optional[str] = None,
        executable: Optional[Path] = None, timeout: float = 300.0,
        env: Optional[Mapping[str, str]] = None) -> subprocess.CompletedProcess:
    """Run the host on ``fmu`` (extracted to a scratch folder) in a bare environment.

    ``env`` replaces the environment (default: ``environment(python)``). Raises
    ``subprocess.CalledProcessError`` on a non-zero exit; the completed process (with its stdout
    and stderr) is returned otherwise.
    """
    executable = Path(executable) if executable is not None else build()
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_native_") as scratch:
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(scratch)
        command = [str(executable), scratch, str(out_csv), *args]
        completed = subprocess.run(command, env=dict(env) if env is not None else environment(python),
                                   capture_output=True, text=True, timeout=timeout)
    if completed.returncode != 0:
        raise subprocess.CalledProcessError(completed.returncode, command, completed.stdout, completed.stderr)
    return completed
