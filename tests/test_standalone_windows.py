"""The standalone FMUs (:mod:`piezo_fmu.build.standalone`) on Windows: the C host, cross-compiled
with mingw-w64, runs them under Wine in a fresh prefix where no Python is installed, with nothing
on ``WINEPATH`` and no variable of the project set (``tests/windows.py``'s bare environment).

1. The prefix has no Python: the normal FMU fails there with the loader's "no Python" message.
2. The nominal case runs cleanly in both FMI versions and agrees with fmpy on Linux to the
   tolerances of ``tests/test_windows.py`` (its normal FMUs' runs, with the same embeddable
   CPython 3.13.2 and numpy 2.1.3, agree with fmpy on Linux to the same bounds).
3. Every refusal, the bad start value included, returns Error; after Reset the same instance runs
   the cross-check scenario, which agrees with fmpy on Linux as well.
4. A normal FMU beside the standalone one in one process uses the interpreter the standalone one
   started, with the same bits.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests import windows  # noqa: E402
from tests.test_loader import extract  # noqa: E402
from tests.test_windows import HARMONIC, NOMINAL, assert_agrees_with_linux, fmu_dirs, host, run_host  # noqa: E402,F401


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> dict[str, str]:
    """The environment's only addition: a Wine prefix made for this module, where nothing was installed."""
    return {"WINEPREFIX": str(windows.wine_prefix(tmp_path_factory.mktemp("wine") / "prefix"))}


@pytest.fixture(scope="module")
def standalone_dirs(standalone_fmus, tmp_path_factory) -> dict[int, Path]:
    return {version: extract(fmu, tmp_path_factory.mktemp(f"standalone{version}"))
            for version, fmu in standalone_fmus.items()}


def test_the_fresh_prefix_has_no_python_for_the_normal_fmu(host, fmu_dirs, fresh, tmp_path):
    completed = run_host(host, fmu_dirs[2], tmp_path / "out.csv", ("--stop", "0.01"), fresh)
    assert completed.returncode == 1
    assert completed.stderr.startswith("[native_host] logStatusError (Error): piezo-fmu: no Python for this FMU: "
                                       "PIEZO_FMU_PYTHON is unset; there is no py launcher; there is no python.exe")


@pytest.mark.parametrize("version", [2, 3])
def test_with_no_python_installed_the_standalone_fmu_runs_the_nominal_case_cleanly_and_agrees_with_fmpy_on_linux(
        host, standalone_dirs, fresh, tmp_path, version):
    out = tmp_path / "standalone.csv"
    completed = run_host(host, standalone_dirs[version], out, NOMINAL, fresh)
    assert completed.returncode == 0, completed.stderr  # any status but OK would be exit status 1
    assert completed.stderr == "" and completed.stdout == ""
    assert_agrees_with_linux(out, "nominal")


@pytest.mark.parametrize("version", [2, 3])
def test_with_no_python_installed_every_refusal_returns_error_and_after_reset_the_cross_check_agrees_with_fmpy(
        host, standalone_dirs, fresh, tmp_path, version):
    """The refusals and the cross-check scenario in one run (each Wine start costs seconds): the
    instance refuses every bad call with Error, is reset, and then runs the scenario."""
    out = tmp_path / "standalone.csv"
    completed = run_host(host, standalone_dirs[version], out, (*HARMONIC, "--refusals"), fresh)
    assert completed.returncode == 0, completed.stderr  # each refusal returned Error, everything else OK
    assert ("(Error): invalid start values: m = -1.0 kg is out of range; allowed range (0, inf)\n"
            "native_host: refused as it must be (Error): exiting initialization with m = -1\n") in completed.stderr
    assert completed.stderr.count("refused as it must be (Error)") == 16
    assert "Fatal" not in completed.stderr
    assert_agrees_with_linux(out, "harmonic")


def test_with_no_python_installed_a_normal_fmu_beside_the_standalone_one_uses_its_interpreter(
        host, standalone_dirs, fmu_dirs, fresh, tmp_path):
    """The standalone FMU starts its CPython; the normal FMU, which finds none in this prefix alone,
    finds it in the process, and both give the same bits."""
    out = tmp_path / "out.csv"
    completed = run_host(host, standalone_dirs[2], out, (*NOMINAL, "--also", windows.windows_path(fmu_dirs[2])), fresh)
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == ""
    assert_agrees_with_linux(out, "nominal")
    assert Path(f"{out}.also").read_bytes() == out.read_bytes()
