"""Where numba keeps the kernel's compiled CPU code: one folder for every version of the batch
engine's source, shared by every copy of it.

numba keys a cached function by its source file's content and its bytecode, but puts it in a folder
named after the file's directory. A host process that loaded an FMU imports ``piezo_fmu`` from the
FMU's unpacked copy, in a fresh temporary folder each time, and would compile the kernel anew in
every such process. The locator installed here keeps the compiled code of every function of the
batch engine (``piezo_fmu/solver/batch``), from wherever it was imported, in one folder named by the
content of all the engine's files (:func:`version_folder`): every copy with the same content finds
it, and a changed file, even one whose functions did not change, means a fresh folder (a function's
compiled code holds the functions it calls, compiled as their registration said: the content of one
file alone does not tell whether it is still valid). numba's other functions are untouched.

A folder that cannot be written (a home that is not the user's, a read-only container) would make
numba refuse to compile at all: :func:`unwritable` says why beforehand, and the kernel is then
compiled for its process alone.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
from pathlib import Path

#: The batch engine's package folder, whose files' content names the cache's folder.
PACKAGE = Path(__file__).resolve().parents[1]
#: The last parts of that folder's path, in any copy of the package.
PARTS = ("piezo_fmu", "solver", "batch")


def cache_dir() -> Path:
    """Where the compiled CPU code is kept: ``$NUMBA_CACHE_DIR``, else ``~/.cache/piezo-fmu/numba``
    (``$XDG_CACHE_HOME`` respected)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "piezo-fmu" / "numba"


def version_folder(folder: Path, package: Path = PACKAGE) -> Path:
    """The folder under ``folder`` for this content of the engine's source files (every ``*.py``
    under ``package``, by their path in it): their SHA-256 together, with numba's version."""
    import numba

    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return Path(folder) / digest.hexdigest()[:16]


def unwritable(folder: Path) -> str | None:
    """Why compiled code cannot be kept in ``folder`` (None when it can): numba's own test, the
    folder made and a temporary file written in it."""
    import tempfile

    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        return f"{type(error).__name__}: {error}"
    return None


def _in_package(py_file: str) -> bool:
    """Whether ``py_file`` lies in a copy of the batch engine's package, at any depth."""
    parts = Path(py_file).parent.parts
    return any(parts[k:k + len(PARTS)] == PARTS for k in range(len(parts) - len(PARTS) + 1))


def install(folder: Path) -> None:
    """Put the locator in front of numba's own, once per process: the compiled code of the batch
    engine's functions is kept in ``folder`` (its :func:`version_folder`)."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    if any(getattr(cls, "_piezo_fmu", False) for cls in impl._locator_classes):
        return

    class KernelLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        _piezo_fmu = True

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = str(folder)

        def get_cache_path(self):
            return self._cache_path

        @classmethod
        def from_function(cls, py_func, py_file):
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

    impl._locator_classes = [KernelLocator] + list(impl._locator_classes)


@contextlib.contextmanager
def folder_lock(folder: Path):
    """Hold an exclusive lock on ``folder`` (a file ``.lock`` in it) against other processes, waiting
    for it."""
    with open(Path(folder) / ".lock", "a+b") as handle:
        if os.name == "nt":
            import msvcrt

            handle.seek(0)
            while True:
                try:
                    msvcrt.locking(handle.fileno(), msvcrt.LK_LOCK, 1)
                    break
                except OSError:  # LK_LOCK gives up after ten seconds: wait on
                    continue
            try:
                yield
            finally:
                handle.seek(0)
                msvcrt.locking(handle.fileno(), msvcrt.LK_UNLCK, 1)
        else:
            import fcntl

            fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


class first_call_locked:
    """``dispatcher`` (a compiled entry point), whose first call in this process holds
    :func:`folder_lock` on ``folder``: the call that compiles it, or loads it from the cache."""

    def __init__(self, dispatcher, folder: Path):
        self.dispatcher, self._folder = dispatcher, folder
        self._lock = threading.Lock()
        self._warm = False

    def __call__(self, *args):
        if not self._warm:
            with self._lock, folder_lock(self._folder):
                result = self.dispatcher(*args)
                self._warm = True
            return result
        return self.dispatcher(*args)
