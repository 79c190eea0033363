"""A user who is not root, with a bare ``PATH`` and a Python it can run, for the tests of what
``make nominal`` needs (``tests/test_python_only.py``).

Run as root (CI), :func:`user` creates a system user for the module's tests (``useradd``; removed
afterwards) and :func:`run` runs a command as that user with ``runuser``; run as anyone else, the
tests' own user is already not root and runs it directly. Either way the command gets only the
environment it is given (``env -i``).

:func:`python_env` gives that user a virtual environment holding this environment's packages
(a ``.pth`` file adds its site-packages) without installing anything, which is the slow part
of a fresh ``make nominal`` (a minute or two, from the package registries). Where the user cannot
run this environment's base interpreter (pyenv's, under root's home), the environment is made
from a copy of it: the same executable, libpython and standard library, in the user's folder.
"""

from __future__ import annotations

import os
import pwd
import shutil
import stat
import subprocess
import sys
import sysconfig
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional

#: The user the tests create when they run as root.
NAME = "piezo-fmu-nonroot"


@contextmanager
def user() -> Iterator[Optional[str]]:
    """A user who is not root: a new one when we are root (None: we are not root ourselves)."""
    if os.geteuid() != 0:
        yield None
        return
    created = subprocess.run(["getent", "passwd", NAME], capture_output=True).returncode != 0
    if created:
        subprocess.run(["useradd", "--system", "--no-create-home", "--shell", "/usr/sbin/nologin", NAME],
                       check=True, capture_output=True)
    try:
        yield NAME
    finally:
        if created:
            subprocess.run(["userdel", NAME], capture_output=True)


def run(name: Optional[str], argv: list, cwd: Path, env: dict, timeout: float = 120) -> subprocess.CompletedProcess:
    """``argv`` as the user ``name`` (None: as ourselves) in ``cwd`` with exactly ``env``."""
    prefix = [] if name is None else [shutil.which("runuser"), "-u", name, "--"]
    command = [*prefix, shutil.which("env"), "-i", *(f"{key}={value}" for key, value in env.items()), *map(str, argv)]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def give(name: Optional[str], folder: Path) -> None:
    """Make ``folder`` and everything in it the user's."""
    if name is None:
        return
    entry = pwd.getpwnam(name)
    for path in [folder, *folder.rglob("*")]:
        os.lchown(path, entry.pw_uid, entry.pw_gid)


def bare_path(folder: Path, tools: tuple[str, ...]) -> Path:
    """A folder holding links to ``tools`` (found on this PATH, or in /usr/sbin, /sbin), and nothing
    else: the whole PATH of a command that must not find a compiler or Wine."""
    folder.mkdir(parents=True, exist_ok=True)
    search = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"])
    for tool in tools:
        found = shutil.which(tool, path=search)
        assert found, f"{tool} is not installed"
        (folder / tool).symlink_to(found)
    return folder


def _copy_interpreter(dest: Path) -> tuple[Path, dict]:
    """This environment's base interpreter, copied into ``dest``: its executable, its libpython
    and its standard library (without site-packages and the test suites)."""
    executable = Path(os.path.realpath(sys._base_executable))
    stdlib = Path(sysconfig.get_paths()["stdlib"])
    (dest / "bin").mkdir(parents=True)
    shutil.copy2(executable, dest / "bin" / executable.name)
    shutil.copytree(stdlib, dest / "lib" / stdlib.name, symlinks=True, ignore=shutil.ignore_patterns(
        "site-packages", "test", "idlelib", "tkinter", "turtledemo", "ensurepip"))
    if sysconfig.get_config_var("Py_ENABLE_SHARED"):
        libdir = Path(sysconfig.get_config_var("LIBDIR"))
        for library in libdir.glob(f"{sysconfig.get_config_var('LDLIBRARY')}*"):
            shutil.copy2(library, dest / "lib" / library.name, follow_symlinks=False)
    return dest / "bin" / executable.name, {"LD_LIBRARY_PATH": str(dest / "lib")}


def python_env(name: Optional[str], folder: Path, sources: Path) -> tuple[Path, dict]:
    """A virtual environment in ``folder`` that the user ``name`` can run, importing the package
    from ``sources`` (a ``src`` folder) and everything else from this environment, with the
    ``piezo-fmu`` command; and the variables its interpreter needs."""
    base, variables = Path(os.path.realpath(sys._base_executable)), {}
    if run(name, [base, "-c", "import encodings"], cwd=Path("/"), env={}).returncode != 0:
        base, variables = _copy_interpreter(folder / "python")
    venv = folder / "venv"
    subprocess.run([base, "-m", "venv", "--without-pip", venv], check=True, capture_output=True,
                   env={**os.environ, **variables})
    site_packages = Path(sysconfig.get_paths(vars={"base": str(venv), "platbase": str(venv)})["purelib"])
    ours = sysconfig.get_paths()["purelib"]
    private = [str(path) for path in (Path(ours), *Path(ours).parents) if not path.stat().st_mode & stat.S_IXOTH]
    assert name is None or not private, (
        f"the user {name} cannot read this environment's packages in {ours}: {private[-1]} is private to its "
        "owner (mktemp -d makes such a folder); run the suite from a clone that other users can read")
    (site_packages / "piezo_fmu_nonroot.pth").write_text(f"{sources}\nimport site; site.addsitedir({ours!r})\n")
    script = venv / "bin" / "piezo-fmu"
    script.write_text(f"#!{venv / 'bin' / 'python'}\nimport sys\nfrom piezo_fmu_harness.cli import main\n"
                      "sys.exit(main())\n")
    script.chmod(0o755)
    return venv, variables
