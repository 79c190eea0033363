"""The FMUs' own binary: a loader in front of pythonfmu's, built for Linux and Windows.

``loader.c`` (its header comment says what it does) is compiled once per FMI version and
platform, with the forwarders that :mod:`.generate` writes from the standard's headers and the
platform's layer (``platform_posix.c`` with the system C compiler, ``platform_windows.c`` with
mingw-w64's ``x86_64-w64-mingw32-gcc``), and :func:`install_loader` puts it into an FMU's files
in place of pythonfmu's binaries, which the FMU keeps beside it under the name the loader looks
for:

=========  ================================================  ====================================================
FMI        the loader (what hosts load)                      pythonfmu's binary
=========  ================================================  ====================================================
2.0        ``binaries/linux64/<id>.so``                      ``binaries/linux64/<id>.pythonfmu.so``
2.0        ``binaries/win64/<id>.dll``                       ``binaries/win64/<id>.pythonfmu.dll``
3.0        ``binaries/x86_64-linux/<id>.so``                 ``binaries/x86_64-linux/<id>.pythonfmu.so``
3.0        ``binaries/x86_64-windows/<id>.dll``              ``binaries/x86_64-windows/<id>.pythonfmu.dll``
=========  ================================================  ====================================================

The build is byte-reproducible with the same compilers: it runs in a scratch folder under fixed
relative file names, with no debug information, no build ID, no PE timestamp
(``--no-insert-timestamp``), and the result stripped.

Neither compiler is needed to rebuild the committed FMUs: where one is absent,
:func:`loader_binary` takes that platform's binary from the committed FMU, provided
:mod:`.manifest` shows that it is the binary the current sources give.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Optional

from ..archive import files_of
from . import manifest
from .generate import fmi_headers, generate

HERE = Path(__file__).resolve().parent
SOURCES = {"linux": ("loader.c", "platform.h", "platform_posix.c"),
           "windows": ("loader.c", "platform.h", "platform_windows.c")}
PLATFORMS = ("linux", "windows")
#: Folder of each platform's binary in the archive, per FMI version.
BINARIES = {("linux", 2): "binaries/linux64", ("linux", 3): "binaries/x86_64-linux",
            ("windows", 2): "binaries/win64", ("windows", 3): "binaries/x86_64-windows"}
LINUX_BINARIES = {2: BINARIES["linux", 2], 3: BINARIES["linux", 3]}
WINDOWS_BINARIES = {2: BINARIES["windows", 2], 3: BINARIES["windows", 3]}
#: A binary's file name ending, and the one pythonfmu's binary gets beside the loader (the
#: loader derives it from its own name).
LIBRARY_SUFFIX = {"linux": ".so", "windows": ".dll"}
REAL_SUFFIXES = {"linux": ".pythonfmu.so", "windows": ".pythonfmu.dll"}
REAL_SUFFIX = REAL_SUFFIXES["linux"]
WARNINGS = ("-std=c11", "-O2", "-shared", "-Wall", "-Wextra", "-Werror", "-s")
CFLAGS = {"linux": (*WARNINGS, "-fPIC", "-fvisibility=hidden", "-Wl,--build-id=none", "-Wl,-z,defs"),
          # no PE timestamp, and libgcc linked in: the DLL imports only what Windows has
          "windows": (*WARNINGS, "-Wl,--no-insert-timestamp", "-static-libgcc")}
LIBRARIES = {"linux": ("-ldl", "-lpthread"), "windows": ()}
#: The mingw-w64 cross compiler (Debian: gcc-mingw-w64-x86-64, installed by ``make system-deps``).
MINGW = "x86_64-w64-mingw32-gcc"


def compiler(platform: str = "linux") -> str:
    """The C compiler for ``platform``: ``$CC``, ``cc`` or ``gcc`` on PATH for linux, mingw-w64 for windows."""
    if platform == "windows":
        cc = os.environ.get("MINGW_CC") or shutil.which(MINGW)
        if not cc:
            raise FileNotFoundError(f"no {MINGW}: install mingw-w64 (`make system-deps`, or Debian: "
                                    "apt-get install gcc-mingw-w64-x86-64)")
        return cc
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise FileNotFoundError("no C compiler: install one (Debian: apt-get install gcc)")
    return cc


def _command(fmi_version: int, platform: str, cc: str, scratch: str, headers: str) -> list[str]:
    """The compiler's command line in ``scratch``, which holds the sources and ``forwarders.inc``."""
    return [cc, *CFLAGS[platform], f"-DFMI_VERSION={fmi_version}", '-DFORWARDERS="forwarders.inc"',
            f"-ffile-prefix-map={scratch}=.", "-I", headers,
            *(name for name in SOURCES[platform] if name.endswith(".c")), "-o", f"loader{LIBRARY_SUFFIX[platform]}",
            *LIBRARIES[platform]]


def _platform_checked(platform: str) -> None:
    if platform not in SOURCES:
        raise ValueError(f"platform = {platform!r}; allowed values {PLATFORMS}")


@lru_cache(maxsize=None)
def compile_loader(fmi_version: int, platform: str = "linux") -> bytes:
    """The loader's shared library for FMI ``fmi_version`` (2 or 3) on ``platform`` ("linux" or
    "windows"), compiled here (warnings are errors)."""
    _platform_checked(platform)
    forwarders = generate(fmi_version)
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_loader_") as scratch:
        for name in SOURCES[platform]:
            shutil.copyfile(HERE / name, Path(scratch) / name)
        (Path(scratch) / "forwarders.inc").write_text(forwarders)
        command = _command(fmi_version, platform, compiler(platform), scratch, str(fmi_headers()))
        completed = subprocess.run(command, cwd=scratch, capture_output=True, text=True)
        if completed.returncode != 0:
            raise RuntimeError(f"compiling the FMI {fmi_version} loader for {platform} failed:\n{completed.stderr}")
        return (Path(scratch) / command[command.index("-o") + 1]).read_bytes()


@lru_cache(maxsize=None)
def loader_inputs(fmi_version: int, platform: str = "linux") -> dict[str, str]:
    """The SHA-256 of each input of :func:`compile_loader`: the C sources, the generated
    forwarders, the FMI headers they include, and the compiler's arguments (with the compiler,
    the scratch folder and the headers' folder left out: they name no content)."""
    _platform_checked(platform)
    digests = {name: manifest.sha256((HERE / name).read_bytes()) for name in SOURCES[platform]}
    digests["forwarders.inc"] = manifest.sha256(generate(fmi_version).encode())
    headers = sorted(fmi_headers().glob("fmi[23]*.h"))
    digests["FMI headers"] = manifest.sha256(b"".join(h.name.encode() + b"\0" + h.read_bytes() + b"\0" for h in headers))
    arguments = _command(fmi_version, platform, "CC", "SCRATCH", "FMI_HEADERS")
    digests["compiler arguments"] = manifest.sha256("\0".join(arguments).encode())
    return digests


def missing_compilers() -> list[str]:
    """The platforms whose compiler is not installed here."""
    missing = []
    for platform in PLATFORMS:
        try:
            compiler(platform)
        except FileNotFoundError:
            missing.append(platform)
    return missing


def loaders_in(files: dict[str, bytes], fmi_version: int) -> dict[str, bytes]:
    """The loader binary of each platform in an FMU's ``files`` (archive names to bytes)."""
    found = {}
    for platform in PLATFORMS:
        folder, suffix = BINARIES[platform, fmi_version] + "/", LIBRARY_SUFFIX[platform]
        names = [name for name in files if name.startswith(folder) and name.endswith(suffix)
                 and not name.endswith(REAL_SUFFIXES[platform]) and "/" not in name[len(folder):]]
        if len(names) == 1:
            found[platform] = files[names[0]]
    return found


def _committed_loaders(fmu: Path, fmi_version: int) -> dict[str, bytes]:
    return loaders_in(files_of(Path(fmu).read_bytes()), fmi_version) if Path(fmu).is_file() else {}


def loader_binary(fmi_version: int, platform: str = "linux", committed: Optional[Path] = None) -> bytes:
    """The loader for FMI ``fmi_version`` on ``platform``: compiled where its compiler is installed;
    elsewhere the one the ``committed`` FMU carries, if :mod:`.manifest` shows that it is the
    binary these sources give (else :class:`.manifest.LoaderUnavailable`)."""
    try:
        compiler(platform)
    except FileNotFoundError as missing:
        if committed is None:
            raise
        return manifest.committed_binary(fmi_version, platform, loader_inputs(fmi_version, platform),
                                         _committed_loaders(committed, fmi_version).get(platform), committed, missing)
    return compile_loader(fmi_version, platform)


def manifest_entries(files: dict[str, bytes], fmi_version: int) -> dict:
    """The manifest's entries for the loaders in an FMU's ``files``, built from these sources."""
    return {manifest.key(fmi_version, platform): manifest.entry(loader_inputs(fmi_version, platform), binary)
            for platform, binary in loaders_in(files, fmi_version).items()}


def manifest_problems(files: dict[str, bytes], fmi_version: int) -> list[str]:
    """Where the manifest disagrees with these sources or with the loaders in an FMU's ``files``."""
    return manifest.problems(fmi_version, loaders_in(files, fmi_version),
                             {platform: loader_inputs(fmi_version, platform) for platform in PLATFORMS})


def install_loader(files: dict[str, bytes], fmi_version: int, model_identifier: str,
                   platforms: tuple[str, ...] = PLATFORMS, committed: Optional[Path] = None) -> dict[str, bytes]:
    """An FMU's files with the loader as its binary of each of ``platforms`` and pythonfmu's
    binary renamed beside it.

    ``files`` maps archive names to bytes, as the FMU build has them; it is not changed. Where a
    platform's compiler is absent, the loader comes from the ``committed`` FMU (see
    :func:`loader_binary`).
    """
    if fmi_version not in (2, 3):
        raise ValueError(f"FMI version {fmi_version}: the loader exists for 2 and 3")
    installed = dict(files)
    for platform in platforms:
        folder, suffix = BINARIES[platform, fmi_version], LIBRARY_SUFFIX[platform]
        binary = f"{folder}/{model_identifier}{suffix}"
        if binary not in files:
            raise KeyError(f"the FMU has no {binary} (pythonfmu's {platform} binary) to put the loader in front of")
        installed[f"{folder}/{model_identifier}{REAL_SUFFIXES[platform]}"] = installed.pop(binary)
        installed[binary] = loader_binary(fmi_version, platform, committed)
    return installed
