"""``make nominal`` needs only python3: no system package manager, no root, no C
compiler, no Wine.

- ``make -n nominal`` calls no system package manager (no apt, apt-get, dpkg, sudo, nothing of
  ``system-deps``), where ``make -n test`` does.
- Without any compiler on ``PATH``, ``python -m piezo_fmu.build --check`` rebuilds both committed
  FMUs byte for byte, with the loader binaries of the committed FMUs.
- A loader source changed by one byte, without a compiler: the build stops with an error that
  names the changed file and the compiler to install, and writes nothing; with a C compiler but
  no mingw-w64, only the windows loader is refused.
- The committed manifest is what the build writes from the committed FMUs and the sources;
  ``--check`` fails when it disagrees with an FMU's binary, and no FMU bundles it.
- As a user who is not root, with a ``PATH`` of ``make`` alone, in a fresh copy of the
  repository's files, ``make nominal`` rebuilds the FMUs byte for byte and runs the nominal case;
  ``make system-deps`` as that user prints the one ``apt-get`` command and fails. The user's
  environment reuses this one's packages (:mod:`tests.nonroot`): the package installation from
  the registries is the one part of a fresh ``make nominal`` these tests do not run.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from piezo_fmu.build import fmus as build
from piezo_fmu.build import loader
from piezo_fmu.build.loader import manifest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests import nonroot  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PACKAGE_MANAGERS = re.compile(r"\b(apt-get|aptitude|apt|dpkg|sudo|ldconfig|wine64|mingw)\b")
COMPILERS_AND_WINE = ("cc", "gcc", "x86_64-w64-mingw32-gcc", "wine", "wine64")


def bare_env(path: Path, **extra: str) -> dict:
    """This process's environment with ``path`` as the whole PATH and no compiler named."""
    drop = {"PATH", "CC", "MINGW_CC", "PYTHONPATH", "PIEZO_FMU"}
    return {**{k: v for k, v in os.environ.items() if k not in drop}, "PATH": str(path), **extra}


def build_without_compilers(tmp_path: Path, cwd: Path, *argv: str, tools: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """``python -m piezo_fmu.build ARGV`` in ``cwd`` with a PATH of a link to this Python and ``tools``."""
    bin_dir = nonroot.bare_path(tmp_path / "bin", tools)
    (bin_dir / "python").symlink_to(sys.executable)
    assert not [tool for tool in COMPILERS_AND_WINE if tool not in tools and shutil.which(tool, path=str(bin_dir))]
    env = bare_env(bin_dir, **({"PYTHONPATH": str(cwd / "src")} if cwd != ROOT else {}))
    return subprocess.run([sys.executable, "-m", "piezo_fmu.build", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def sources(tmp_path) -> Path:
    """A copy of the package's sources and of the committed FMUs, to change."""
    copy = tmp_path / "copy"
    shutil.copytree(ROOT / "src" / "piezo_fmu", copy / "src" / "piezo_fmu", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "fmus", copy / "fmus")
    return copy


def change_one_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    at = data.index(b"loader")
    data[at] = ord("L")
    path.write_bytes(bytes(data))


def unchanged(copy: Path) -> bool:
    """The copy's FMUs and manifest are still the committed ones."""
    pairs = [(copy / target.dest, ROOT / target.dest) for target in build.TARGETS.values()]
    pairs.append((copy / manifest.MANIFEST.relative_to(ROOT), manifest.MANIFEST))
    return all(a.read_bytes() == b.read_bytes() for a, b in pairs)


# -- make -n -----------------------------------------------------------------------------------------

def test_make_n_nominal_calls_no_system_package_manager(tmp_path):
    fresh = tmp_path / "venv"  # no stamp: the dry run shows the installation too
    nominal = subprocess.run(["make", "-n", "nominal", f"VENV={fresh}"], cwd=ROOT, capture_output=True, text=True)
    assert nominal.returncode == 0, nominal.stderr
    assert f"python3 -m venv {fresh}" in nominal.stdout
    assert f"{fresh}/bin/python -m pip install -q --disable-pip-version-check -e .\n" in nominal.stdout
    assert f"{fresh}/bin/python -m piezo_fmu.build\n{fresh}/bin/piezo-fmu nominal --force\n" in nominal.stdout
    assert PACKAGE_MANAGERS.findall(nominal.stdout) == [], nominal.stdout
    assert "[test]" not in nominal.stdout  # the test extras are make test's
    test = subprocess.run(["make", "-n", "test", f"VENV={fresh}"], cwd=ROOT, capture_output=True, text=True)
    assert {"apt-get", "sudo", "ldconfig"} <= set(PACKAGE_MANAGERS.findall(test.stdout)), test.stdout
    assert "-e '.[test]'" in test.stdout


# -- the build without compilers ---------------------------------------------------------------------

def test_without_any_compiler_the_build_reproduces_both_committed_fmus_byte_for_byte(tmp_path):
    done = build_without_compilers(tmp_path, ROOT, "--check")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "no compiler here for the linux and windows loaders: reusing the committed FMUs'" in done.stdout
    for target in build.TARGETS.values():
        assert f"{target.dest} is up to date" in done.stdout


def test_a_changed_loader_source_without_a_compiler_stops_the_build_and_names_it(tmp_path, sources):
    change_one_byte(sources / "src" / "piezo_fmu" / "build" / "loader" / "loader.c")
    for argv in ((), ("--check",)):
        done = build_without_compilers(tmp_path / "-".join(argv or ["write"]), sources, *argv)
        assert done.returncode == 1, done.stdout + done.stderr
        assert ("error: cannot build the FMI 2 loader for linux: no C compiler: install one (Debian: apt-get install "
                "gcc); and the linux loader of fmus/PiezoImpactDamper.fmu cannot stand in for it (changed since "
                "manifest.json was written: loader.c)") in done.stderr
        assert "is up to date" not in done.stdout and "wrote" not in done.stdout
        assert unchanged(sources)


def test_with_a_c_compiler_but_no_mingw_only_the_windows_loader_must_match_the_manifest(tmp_path, sources):
    change_one_byte(sources / "src" / "piezo_fmu" / "build" / "loader" / "platform_windows.c")
    done = build_without_compilers(tmp_path, sources, "--fmi", "3", tools=("cc", "as", "ld"))
    assert done.returncode == 1, done.stdout + done.stderr
    assert "no compiler here for the windows loaders" in done.stdout
    assert re.findall(r"cannot build the FMI 3 loader for (\w+): no x86_64-w64-mingw32-gcc", done.stderr) == ["windows"]
    assert "changed since manifest.json was written: platform_windows.c)" in done.stderr
    assert unchanged(sources)


# -- the manifest ------------------------------------------------------------------------------------

def test_the_committed_manifest_is_what_the_build_writes(tmp_path, monkeypatch):
    monkeypatch.setattr(manifest, "MANIFEST", tmp_path / "manifest.json")
    monkeypatch.chdir(ROOT)
    build.record_loaders(list(build.TARGETS.values()))
    assert (tmp_path / "manifest.json").read_text() == (ROOT / "src/piezo_fmu/build/loader/manifest.json").read_text()
    assert sorted(manifest.read(tmp_path / "manifest.json")) == ["fmi2-linux", "fmi2-windows", "fmi3-linux",
                                                                 "fmi3-windows"]


def test_check_fails_when_the_manifest_disagrees_with_an_fmus_binary(tmp_path, monkeypatch):
    recorded = json.loads(manifest.MANIFEST.read_text())
    recorded["fmi3-windows"]["binary"] = "0" * 64
    (tmp_path / "manifest.json").write_text(json.dumps(recorded))
    monkeypatch.setattr(manifest, "MANIFEST", tmp_path / "manifest.json")
    problems = build.check(build.FMI3, ROOT / build.FMI3.dest)
    assert len(problems) == 1 and "(fmi3-windows): its SHA-256 is " in problems[0], problems
    assert problems[0].endswith(f"manifest.json records {'0' * 64}")
    def no_compiler(platform: str = "linux") -> str:
        raise FileNotFoundError("none")

    monkeypatch.setattr(loader, "compiler", no_compiler)
    with pytest.raises(manifest.LoaderUnavailable, match="cannot build the FMI 3 loader for windows: none"):
        loader.loader_binary(3, "windows", ROOT / build.FMI3.dest)


@pytest.mark.parametrize("target", list(build.TARGETS.values()), ids=["fmi2", "fmi3"])
def test_no_fmu_bundles_the_manifest(target):
    import zipfile

    with zipfile.ZipFile(ROOT / target.dest) as fmu:
        assert not [name for name in fmu.namelist() if "manifest" in name.lower()]


# -- as a user who is not root -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def user():
    with nonroot.user() as name:
        yield name


@pytest.fixture
def clone(user):
    """A fresh copy of the repository's files (tracked, or new and not ignored), the user's, in a
    folder the user can reach (pytest's own temporary folder is root's alone), with a PATH of
    ``make`` and the few tools ``system-deps`` calls."""
    folder = Path(tempfile.mkdtemp(prefix="piezo_fmu_nonroot_"))
    try:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                capture_output=True, text=True, check=True).stdout.split("\0")
        for name in filter(None, listed):
            if (ROOT / name).is_file():
                (folder / "clone" / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(ROOT / name, folder / "clone" / name)
        (folder / "home").mkdir()
        nonroot.bare_path(folder / "bin", ("make", "id", "grep"))
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_make_nominal_runs_as_a_user_who_is_not_root_without_compilers_in_a_fresh_copy(user, clone):
    venv, variables = nonroot.python_env(user, clone, clone / "clone" / "src")
    (venv / ".installed").touch()  # installed: the package from the copy, the rest from this environment
    nonroot.give(user, clone)
    env = {"PATH": str(clone / "bin"), "HOME": str(clone / "home"), "LANG": "C.UTF-8", **variables}
    done = nonroot.run(user, [clone / "bin" / "make", "nominal", f"VENV={venv}"], cwd=clone / "clone", env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[:3] == ["no compiler here for the linux and windows loaders: reusing the committed FMUs' "
                         "(checked against manifest.json)",
                         "wrote fmus/PiezoImpactDamper.fmu", "wrote fmus/PiezoImpactDamper3.fmu"], done.stdout
    assert lines[3].startswith("nominal case, 2 s simulated") and lines[-1].split() == ["files", "in", "results/nominal"]
    assert PACKAGE_MANAGERS.findall(done.stdout + done.stderr) == []
    assert unchanged(clone / "clone")
    summary = clone / "clone" / "results" / "nominal" / "summary.json"
    assert summary.stat().st_uid != 0 and summary.stat().st_uid == (clone / "clone").stat().st_uid
    assert json.loads(summary.read_text())["fmu"]["path"] == str(clone / "clone" / "fmus" / "PiezoImpactDamper.fmu")


def test_make_system_deps_as_a_user_who_is_not_root_prints_the_one_command_and_fails(user, clone):
    """The user's PATH has no compiler, nor /sbin: ldconfig is still found for libtbb12."""
    nonroot.give(user, clone)
    done = nonroot.run(user, [clone / "bin" / "make", "system-deps"], cwd=clone / "clone",
                       env={"PATH": str(clone / "bin"), "HOME": str(clone / "home")})
    assert done.returncode != 0
    ldconfig = subprocess.run([shutil.which("ldconfig", path="/usr/sbin:/sbin"), "-p"], capture_output=True, text=True)
    missing = ([] if "libtbb.so.12 " in ldconfig.stdout else ["libtbb12"]) + ["gcc", "libc6-dev", "gcc-mingw-w64-x86-64"]
    missing += [] if os.access("/usr/lib/wine/wine64", os.X_OK) else ["wine64"]
    assert done.stderr.splitlines()[:2] == [
        f"missing Debian packages: {' '.join(missing)} (make installs them when run as root); install them with:",
        f"  sudo apt-get install {' '.join(missing)}"], done.stderr
