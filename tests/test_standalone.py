"""The standalone FMUs (``make fmu-standalone``, :mod:`piezo_fmu.build.standalone`) on Linux: they
carry their own CPython and numpy and run where no Python is installed, with the normal FMUs' bits.

1. The C host (``hosts/native_host.c``) runs each with an environment of nothing but
   ``PATH=/nonexistent`` (no ``python3`` anywhere it could find) from a working directory outside
   the repository: the nominal case and the cross-check scenario, bit for bit the normal FMU's
   (which the same host runs with the project's Python on ``PATH``). Every refusal still returns
   Error there, the bad start value included.
2. When its own runtime cannot be loaded, the loader goes on to the normal FMUs' routes, and its
   message says what happened to each.
3. A standalone and a normal FMU (in either order), or two standalone FMUs, in one process share
   one interpreter and give the bits of each alone.
4. A Python host without numpy (``tests/bare_python_host.py``, ctypes only, in a virtual
   environment of the build's CPython): the FMU's own numpy is added and the bits are the normal
   FMU's; when the FMU's numpy is for another CPython, instantiation fails with what is missing.
5. fmpy's ``validate`` finds no problem; each carries the licences of CPython and numpy, its runtime
   needs the glibc the docs name, and the README gives each FMU's size.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from crosscheck import scenario  # noqa: E402
from hosts import native  # noqa: E402
from piezo_fmu.build import runtimes  # noqa: E402
from tests.test_loader import extract, host, python_without_numpy  # noqa: E402,F401

NORMAL = {2: REPO / "fmus" / "PiezoImpactDamper.fmu", 3: REPO / "fmus" / "PiezoImpactDamper3.fmu"}
NOTHING = {"PATH": "/nonexistent"}
CASES = {"nominal": ("--stop", "2.0", "--step", "1e-3"),
         "cross-check": ("--stop", repr(scenario.STOP_TIME), "--step", repr(scenario.STEP_SIZE),
                         "--in", str(scenario.IN_CSV), "--set", "p0=0", "--set", "q0=0")}
#: The oldest glibc the Linux runtime runs on, as README.md and docs/simulators.md give it.
GLIBC = "2.35"


@pytest.fixture(scope="module")
def folders(standalone_fmus, tmp_path_factory) -> dict[str, Path]:
    """Each FMU extracted once: standalone2, standalone3, normal2, normal3."""
    fmus = {**{f"standalone{v}": path for v, path in standalone_fmus.items()},
            **{f"normal{v}": path for v, path in NORMAL.items()}}
    return {name: extract(fmu, tmp_path_factory.mktemp(name)) for name, fmu in fmus.items()}


def run_host(host: Path, fmu_dir: Path, out: Path, args, env) -> subprocess.CompletedProcess:
    """The C host from ``out``'s folder (outside the repository); its exit status is not checked."""
    return subprocess.run([str(host), str(fmu_dir), str(out), *args], capture_output=True, text=True, env=env,
                          cwd=out.parent, timeout=300)


@pytest.fixture(scope="module")
def normal_runs(host, folders, tmp_path_factory) -> dict[tuple[int, str], bytes]:
    """The normal FMUs' CSV of each case, with the project's Python on PATH."""
    runs = {}
    for version in (2, 3):
        for case, args in CASES.items():
            out = tmp_path_factory.mktemp("normal") / "out.csv"
            completed = run_host(host, folders[f"normal{version}"], out, args, native.environment())
            assert completed.returncode == 0, completed.stderr
            runs[version, case] = out.read_bytes()
    return runs


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("version", [2, 3])
def test_with_nothing_but_path_nonexistent_the_standalone_fmu_gives_the_normal_fmus_bits(
        host, folders, normal_runs, tmp_path, version, case):
    out = tmp_path / "out.csv"
    completed = run_host(host, folders[f"standalone{version}"], out, CASES[case], NOTHING)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout == completed.stderr == ""
    assert out.read_bytes() == normal_runs[version, case]


@pytest.mark.parametrize("version", [2, 3])
def test_with_nothing_but_path_nonexistent_every_refusal_of_the_standalone_fmu_returns_error(host, folders,
                                                                                            tmp_path, version):
    completed = run_host(host, folders[f"standalone{version}"], tmp_path / "out.csv", ("--stop", "0.01", "--refusals"),
                         NOTHING)
    assert completed.returncode == 0, completed.stderr  # each refusal returned Error, everything else OK
    assert ("(Error): invalid start values: m = -1.0 kg is out of range; allowed range (0, inf)\n"
            "native_host: refused as it must be (Error): exiting initialization with m = -1\n") in completed.stderr
    assert completed.stderr.count("refused as it must be (Error)") == 16
    assert "Fatal" not in completed.stderr


def test_when_its_own_runtime_cannot_be_loaded_the_loader_goes_on_to_the_routes_of_the_normal_fmus(
        host, standalone_fmus, tmp_path):
    fmu_dir = extract(standalone_fmus[2], tmp_path / "fmu")
    home = fmu_dir / "resources" / "python" / "linux64"
    (home / "library.txt").write_text("lib/libpython-missing.so\n")
    alone = run_host(host, fmu_dir, tmp_path / "out.csv", ("--stop", "0.01"), NOTHING)
    assert alone.returncode == 1
    missing = home / "lib" / "libpython-missing.so"
    assert alone.stderr == (
        "[native_host] logStatusError (Error): piezo-fmu: no Python for this FMU: PIEZO_FMU_PYTHON is unset and there "
        f"is no python3 on PATH=/nonexistent; tried the FMU's own Python ({home}): cannot load {missing} ({missing}: "
        "cannot open shared object file: No such file or directory). Set PIEZO_FMU_PYTHON=/path/to/python, a Python 3 "
        "built with --enable-shared that can import numpy (for example a virtual environment's bin/python).\n"
        "native_host: fmi2Instantiate failed\n")
    with_python = run_host(host, fmu_dir, tmp_path / "out.csv", ("--stop", "0.01"), native.environment())
    assert with_python.returncode == 0, with_python.stderr
    assert (tmp_path / "out.csv").read_text().splitlines()[-1].startswith("0.01,")


@pytest.mark.parametrize("first, second, env", [
    ("standalone2", "normal2", NOTHING),  # the standalone FMU starts its runtime, the normal one uses it
    ("normal2", "standalone2", None),  # the normal FMU starts the project's Python, the standalone one uses it
    ("standalone3", "standalone2", NOTHING),
], ids=["standalone-then-normal", "normal-then-standalone", "two-standalone"])
def test_a_standalone_and_another_fmu_in_one_process_give_the_bits_of_each_alone(
        host, folders, normal_runs, tmp_path, first, second, env):
    out = tmp_path / "out.csv"
    completed = run_host(host, folders[first], out, (*CASES["nominal"], "--also", str(folders[second])),
                         env or native.environment())
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == ""
    assert out.read_bytes() == normal_runs[int(first[-1]), "nominal"]
    assert Path(f"{out}.also").read_bytes() == normal_runs[int(second[-1]), "nominal"]


def bare_python_host(python: Path, fmu_dir: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(python), str(REPO / "tests" / "bare_python_host.py"), str(fmu_dir), "0.1", "1e-3"],
                          capture_output=True, text=True, env={"PATH": "/nonexistent"}, cwd=tmp_path, timeout=120)


def test_a_python_host_without_numpy_gets_the_fmus_own_numpy_when_the_versions_match(
        host, folders, python_without_numpy, tmp_path):
    completed = bare_python_host(python_without_numpy, folders["standalone2"], tmp_path)
    assert completed.returncode == 0, completed.stderr
    row, numpy_file = completed.stdout.splitlines()
    assert Path(numpy_file).is_relative_to(folders["standalone2"] / "resources" / "python" / "linux64")
    reference = tmp_path / "normal.csv"
    assert run_host(host, folders["normal2"], reference, ("--stop", "0.1"), native.environment()).returncode == 0
    assert row == reference.read_text().splitlines()[-1]


def test_a_python_host_without_numpy_whose_version_the_fmus_numpy_does_not_fit_is_told_what_is_missing(
        standalone_fmus, python_without_numpy, tmp_path):
    """The FMU's runtime said to be another CPython's: its numpy cannot serve this one."""
    fmu_dir = extract(standalone_fmus[2], tmp_path / "fmu")
    described = fmu_dir / "resources" / "python" / "linux64" / "runtime.json"
    runtime = json.loads(described.read_text())
    described.write_text(json.dumps({**runtime, "python": "3.99"}))
    completed = bare_python_host(python_without_numpy, fmu_dir, tmp_path)
    assert completed.returncode == 1
    assert (f"piezo-fmu: this process's Python 3.11 cannot import numpy, and this FMU's own numpy {runtime['numpy']} "
            "is built for CPython 3.99: install numpy into the process's Python, or run the FMU in a process without "
            "Python (it then starts its own CPython 3.99)") in completed.stderr
    assert completed.stderr.endswith("bare_python_host: fmi2Instantiate failed\n")


@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_validate_finds_no_problems_and_the_licences_are_inside(standalone_fmus, version):
    assert validate_fmu(str(standalone_fmus[version])) == []
    with zipfile.ZipFile(standalone_fmus[version]) as fmu:
        licences = {name for name in fmu.namelist() if name.startswith("documentation/licenses/")}
        assert fmu.read("resources/python/win64/python313._pth").endswith(b"import site\r\nLib\\site-packages\r\n")
    for prefix in (f"CPython-{sys.version.split()[0]}/", "CPython-3.13.2/", "numpy-2.1.3-win64/",
                   f"numpy-{runtimes.LINUX_NUMPY.split('==')[1]}-linux64/"):
        assert any(name.startswith(f"documentation/licenses/{prefix}") for name in licences), prefix
    assert not any(re.search(r"/(test|tests|idlelib|tkinter|ensurepip)/", name) for name in licences)


def test_the_linux_runtime_needs_the_glibc_the_docs_name(standalone_fmus):
    assert runtimes.glibc_needed(runtimes.linux_libraries(standalone_fmus[2])) == GLIBC
    for doc in ("README.md", "docs/simulators.md"):
        assert f"glibc {GLIBC}" in (REPO / doc).read_text(), doc


@pytest.mark.parametrize("version", [2, 3])
def test_the_docs_give_each_standalone_fmus_size(standalone_fmus, version):
    """docs/simulators.md names each file with its size; the README gives the one size of both."""
    size = standalone_fmus[version].stat().st_size / 1e6
    name = standalone_fmus[version].name
    text = (REPO / "docs" / "simulators.md").read_text()
    stated = re.search(rf"`build/{re.escape(name)}` \((\d+) MB\)", text)
    assert stated, f"docs/simulators.md gives no size of {name}"
    assert abs(int(stated.group(1)) - size) < 1, (stated.group(0), size)
    both = re.search(r"`make fmu-standalone` into `build/` \((\d+) MB each", (REPO / "README.md").read_text())
    assert both, "README.md gives no size of the standalone FMUs"
    assert abs(int(both.group(1)) - size) < 1, (both.group(0), size)
