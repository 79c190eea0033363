"""Where numba keeps the kernel's compiled CPU code: one folder for every version of the source,
shared by every copy of it.

numba keys a cached function by its source file's content (a SHA-256 stamp) and its bytecode, but
puts it in a folder named after the file's directory. A host process that loaded an FMU imports
``piezo_fmu`` from that FMU's unpacked copy, in a fresh temporary folder each time, and would
compile the kernel anew in every such process (tens of seconds). This locator puts the compiled
code of the kernel (:mod:`.kernel_phases`, :mod:`.kernel_source`, :mod:`.kernel_flow`,
:mod:`.kernel_books` and the drivers of :mod:`.kernel`), from wherever it was imported, in one
folder, so every copy with the same content finds it.

**The folder is named by the content of all the kernel's files** (their SHA-256), not only each file's
own: a function's compiled code holds the functions it calls, and :mod:`.kernel` decides how they
are compiled (which are inlined into their callers). In one folder for every version, a caller
compiled under one version's :data:`.kernel.INLINE` stayed valid for another (its own file had not
changed) and was loaded beside code compiled afresh: a cache left so by an ``INLINE`` changed and
changed back crashed the Lyapunov march in about half the processes (a segmentation fault), where
a fresh cache never did. Now a changed file means a fresh folder, compiled once; the old folders
stay until removed (a few MB each). numba's other functions are untouched.

**A folder that cannot be written** (a home that is not the user's, a read-only container) would
make numba refuse to compile at all ("no locator available"): :func:`unwritable` says why before
anything is compiled, and the kernel is then compiled for its process alone, with a warning.
"""

from __future__ import annotations

import os
from pathlib import Path


def version_folder(files: tuple, folder: Path) -> Path:
    """The folder under ``folder`` for this content of ``files``: their SHA-256 together, with
    numba's version."""
    import hashlib

    import numba

    digest = hashlib.sha256(numba.__version__.encode())
    for name in files:
        digest.update(Path(name).read_bytes())
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


def install(files: tuple, folder: Path) -> None:
    """Put the locator in front of numba's own, for the functions of ``files`` (their names, under
    a ``piezo_fmu/solver/batch`` folder), once per process; their compiled code is kept in
    ``folder`` (their :func:`version_folder`)."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    if any(getattr(cls, "_piezo_fmu", False) for cls in impl._locator_classes):
        return
    names = {os.path.basename(f) for f in files}

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
            path = Path(py_file)
            if path.name not in names or path.parent.parts[-3:] != ("piezo_fmu", "solver", "batch"):
                return None
            return super().from_function(py_func, py_file)

    impl._locator_classes = [KernelLocator] + list(impl._locator_classes)
