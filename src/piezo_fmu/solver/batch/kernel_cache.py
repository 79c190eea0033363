"""Where numba keeps the kernel's compiled CPU code: one folder for every copy of the source.

numba keys a cached function by its source file's content (a SHA-256 stamp), but puts it in a
folder named after the file's directory. A host process that loaded an FMU imports ``piezo_fmu``
from that FMU's unpacked copy, in a fresh temporary folder each time, and would compile the kernel
anew in every such process (tens of seconds). This locator puts the compiled code of
the kernel (:mod:`.kernel_source` and the drivers of :mod:`.kernel`), from wherever it was imported, in one folder (:func:`.kernel.cache_dir`), so
every copy with the same content finds it; a changed source has another stamp and is compiled
again. numba's other functions are untouched.
"""

from __future__ import annotations

import os
from pathlib import Path


def install(files: tuple, folder: Path) -> None:
    """Put the locator in front of numba's own, for the functions of ``files`` (their names, under
    a ``piezo_fmu/solver/batch`` folder), once per process."""
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
