"""The FMUs' own binary: a loader in front of pythonfmu's, built with the system C compiler.

``loader.c`` (its header comment says what it does) is compiled once per FMI version, with the
forwarders that :mod:`.generate` writes from the standard's headers, and
:func:`install_loader` puts it into an FMU's files in place of pythonfmu's linux binary, which
the FMU keeps beside it under the name the loader looks for:

=========  ==========================================  =============================================
FMI        the loader (what hosts load)                pythonfmu's binary
=========  ==========================================  =============================================
2.0        ``binaries/linux64/<id>.so``                ``binaries/linux64/<id>.pythonfmu.so``
3.0        ``binaries/x86_64-linux/<id>.so``           ``binaries/x86_64-linux/<id>.pythonfmu.so``
=========  ==========================================  =============================================

The Windows binary stays pythonfmu's: it loads ``python3.dll`` from ``PATH`` by itself.

The build is byte-reproducible with the same compiler: it runs in a scratch folder under fixed
relative file names, with no debug information, no build ID, and the result stripped.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

from .generate import fmi_headers, generate

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "loader.c"
#: Folder of the linux binary in the archive, per FMI version.
LINUX_BINARIES = {2: "binaries/linux64", 3: "binaries/x86_64-linux"}
#: Suffix that pythonfmu's binary gets beside the loader (the loader derives it from its own name).
REAL_SUFFIX = ".pythonfmu.so"
CFLAGS = ("-std=c11", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror",
          "-Wl,--build-id=none", "-Wl,-z,defs", "-s")


def compiler() -> str:
    """The system C compiler: ``$CC``, else ``cc`` or ``gcc`` on PATH."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise FileNotFoundError("no C compiler: install one (Debian: apt-get install gcc)")
    return cc


@lru_cache(maxsize=None)
def compile_loader(fmi_version: int) -> bytes:
    """The loader's shared library for FMI ``fmi_version`` (2 or 3), compiled here (warnings are errors)."""
    forwarders = generate(fmi_version)
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_loader_") as scratch:
        scratch = Path(scratch)
        shutil.copyfile(SOURCE, scratch / "loader.c")
        (scratch / "forwarders.inc").write_text(forwarders)
        command = [compiler(), *CFLAGS, f"-DFMI_VERSION={fmi_version}", '-DFORWARDERS="forwarders.inc"',
                   f"-ffile-prefix-map={scratch}=.", "-I", str(fmi_headers()), "loader.c", "-o", "loader.so",
                   "-ldl", "-lpthread"]
        completed = subprocess.run(command, cwd=scratch, capture_output=True, text=True)
        if completed.returncode != 0:
            raise RuntimeError(f"compiling the FMI {fmi_version} loader failed:\n{completed.stderr}")
        return (scratch / "loader.so").read_bytes()


def install_loader(files: dict[str, bytes], fmi_version: int, model_identifier: str) -> dict[str, bytes]:
    """An FMU's files with the loader as its linux binary and pythonfmu's binary renamed beside it.

    ``files`` maps archive names to bytes, as the FMU build has them; it is not changed.
    """
    if fmi_version not in LINUX_BINARIES:
        raise ValueError(f"FMI version {fmi_version}: the loader exists for 2 and 3")
    binary = f"{LINUX_BINARIES[fmi_version]}/{model_identifier}.so"
    if binary not in files:
        raise KeyError(f"the FMU has no {binary} (pythonfmu's linux binary) to put the loader in front of")
    installed = dict(files)
    installed[f"{LINUX_BINARIES[fmi_version]}/{model_identifier}{REAL_SUFFIX}"] = installed.pop(binary)
    installed[binary] = compile_loader(fmi_version)
    return installed
