"""The standalone FMUs: the project's FMUs with a CPython runtime and numpy inside, for hosts on
machines without Python (Dymola, Simulink, OpenModelica, ... on a colleague's workstation).

Usage (from the repository root; ``make fmu-standalone``)::

    python -m piezo_fmu.build.standalone     # build/PiezoImpactDamper-standalone.fmu, build/PiezoImpactDamper3-standalone.fmu

Each is the normal FMU of its FMI version (:mod:`piezo_fmu.build.fmus`, the same loader, slave,
variables and model identifier) with, in ``resources/python/linux64/`` and
``resources/python/win64/``, the runtimes of :mod:`piezo_fmu.build.runtimes`, each described by
``library.txt`` (the library the loader loads: in a process without Python it tries this runtime
first) and ``runtime.json`` (its CPython and numpy versions and numpy's folder, for
:mod:`piezo_fmu.build.own_numpy`, which the slave imports first: a Python host without numpy gets
the FMU's numpy when the versions match). The licences of CPython and numpy are in
``documentation/licenses/``. Its identity is derived from its content, as the normal FMU's is; it
is compressed (deflate: the runtimes are large) and reproducible from the same inputs.

The standalone FMUs are not committed. :func:`cached` builds each once per content of its inputs
(the normal FMU's bytes, the runtimes' versions, this module and the hook), in the cache the
runtimes use, which keeps the most recently used builds only.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Optional

from piezo_fmu.build import archive, description, fmus, runtimes

HOOK = Path(__file__).with_name("own_numpy.py")
HOOK_MODULE = "piezo_fmu_own_numpy"
#: Where the standalone FMUs go (``make fmu-standalone``).
BUILD = Path("build")
#: How many builds of each FMU :func:`cached` keeps (the most recently used).
KEPT = 8


def dest(target: fmus.Target) -> Path:
    return BUILD / f"{target.model_identifier}-standalone.fmu"


def with_hook(slave: bytes) -> bytes:
    """The slave's source importing the hook first (right after its ``__future__`` import)."""
    future = b"from __future__ import annotations\n"
    if slave.count(future) != 1:
        raise ValueError("the slave has no single `from __future__ import annotations` to import the hook after")
    return slave.replace(future, future + f"\nimport {HOOK_MODULE}  # noqa: F401,E402 (numpy for a host without)\n"
                         .encode())


def standalone_files(files: dict[str, bytes], target: fmus.Target) -> dict[str, bytes]:
    """The normal FMU's ``files`` with the runtimes, the hook and the licences."""
    files = dict(files)
    slave = f"resources/{target.slave_module}.py"
    files[slave] = with_hook(files[slave])
    files[f"resources/{HOOK_MODULE}.py"] = HOOK.read_bytes()
    for folder, make in runtimes.RUNTIMES.items():
        runtime = make()
        root = f"resources/python/{folder}"
        files.update({f"{root}/{name}": data for name, data in runtime.files.items()})
        files[f"{root}/library.txt"] = runtime.library.encode() + b"\n"
        files[f"{root}/runtime.json"] = json.dumps({"python": runtime.python, "numpy": runtime.numpy,
                                                    "site_packages": runtime.site_packages}, indent=1).encode() + b"\n"
        files.update({f"documentation/licenses/{name}": data for name, data in runtime.licenses.items()})
    root = ET.fromstring(files["modelDescription.xml"])
    root.set(target.identity, "")
    root.set(target.identity, archive.content_identity(files, description.xml_bytes(root)))
    files["modelDescription.xml"] = description.xml_bytes(root)
    return files


def build_bytes(target: fmus.Target, normal: Optional[bytes] = None) -> bytes:
    """The standalone FMU of ``target``, from the ``normal`` FMU's bytes (default: built now)."""
    normal = fmus.build_bytes(target) if normal is None else normal
    return archive.deterministic_zip(standalone_files(archive.files_of(normal), target), zipfile.ZIP_DEFLATED)


def cached(target: fmus.Target) -> Path:
    """The standalone FMU of ``target`` from the current sources, built once per content of its
    inputs (the normal FMU, the runtimes' versions, this module and the hook)."""
    normal = fmus.build_bytes(target)
    key = hashlib.sha256(b"\0".join([normal, Path(__file__).read_bytes(), HOOK.read_bytes(),
                                     Path(runtimes.__file__).read_bytes(), runtimes.LINUX_NUMPY.encode(),
                                     sys.version.encode()])).hexdigest()[:16]
    path = runtimes.CACHE / "standalone" / key / dest(target).name
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(path.name + ".partial")
        partial.write_bytes(build_bytes(target, normal))
        partial.replace(path)
    path.parent.touch()
    _prune(path.parent.parent)
    return path


def _prune(folder: Path) -> None:
    """Keep the :data:`KEPT` most recently used builds in the cache (each is 48 MB; every change of
    the sources makes a new one, and several checkouts may share the cache)."""
    used = sorted((entry for entry in folder.iterdir() if entry.is_dir()), key=lambda entry: entry.stat().st_mtime)
    for entry in used[:-KEPT]:
        shutil.rmtree(entry, ignore_errors=True)


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m piezo_fmu.build.standalone", description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmi", type=int, choices=sorted(fmus.TARGETS), action="append",
                        help="the FMI version of the FMU to build (repeat for both; default: both)")
    args = parser.parse_args(argv)
    for version in args.fmi or sorted(fmus.TARGETS):
        target = fmus.TARGETS[version]
        path = dest(target)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(cached(target).read_bytes())
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    print(f"its Linux runtime needs glibc {runtimes.glibc_needed(runtimes.linux_libraries(path))} or newer")
    return 0


if __name__ == "__main__":
    sys.exit(main())
