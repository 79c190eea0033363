"""A standalone FMU's numpy for a Python host that has none (:mod:`piezo_fmu.build.standalone`).

Inside a standalone FMU this file is the top-level module ``piezo_fmu_own_numpy`` in ``resources/``,
and the slave imports it before anything else. In a process whose Python imports numpy (its own,
or the FMU's runtime that the loader started in a process without Python) nothing changes. Else
the FMU's numpy for this platform (``resources/python/<platform>/``, described by
``runtime.json``) goes to the end of ``sys.path`` when it was built for this Python's version;
otherwise the import fails with what is missing, which the host's logger receives with the
instantiation's failure. It imports nothing of ``piezo_fmu``, which needs numpy.
"""

import importlib.util
import json
import os
import sys

#: The runtime's folder under ``resources/python/`` by ``sys.platform`` (the loader's PLATFORM_RUNTIME).
FOLDERS = {"linux": "linux64", "win32": "win64"}


def add_own_numpy(resources: str):
    """The folder added to ``sys.path`` (None when numpy was importable already)."""
    if importlib.util.find_spec("numpy") is not None:
        return None
    this = "%d.%d" % sys.version_info[:2]
    folder = os.path.join(resources, "python", FOLDERS.get(sys.platform, sys.platform))
    try:
        with open(os.path.join(folder, "runtime.json")) as file:
            runtime = json.load(file)
    except OSError:
        raise ImportError(f"piezo-fmu: this process's Python {this} cannot import numpy, and this FMU carries no "
                          f"runtime for {sys.platform}: install numpy into that Python") from None
    if runtime["python"] != this:
        raise ImportError(f"piezo-fmu: this process's Python {this} cannot import numpy, and this FMU's own numpy "
                          f"{runtime['numpy']} is built for CPython {runtime['python']}: install numpy into the "
                          f"process's Python, or run the FMU in a process without Python (it then starts its own "
                          f"CPython {runtime['python']})")
    packages = os.path.join(folder, *runtime["site_packages"].split("/"))
    sys.path.append(packages)
    return packages


add_own_numpy(os.path.dirname(os.path.abspath(__file__)))
