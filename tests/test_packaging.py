"""piezo-fmu as a user installs it.

- ``python -m build`` makes an sdist and, from it, a wheel; ``twine check --strict`` accepts both.
- The wheel carries the committed FMUs, byte for byte, and installs no generic top-level name.
- In a fresh virtual environment, with nothing but the wheel and its dependencies from the package
  index, ``piezo-fmu nominal`` runs from an unrelated directory, finds the FMU installed with the
  package, and writes ``./results/nominal``; ``import harness`` fails there.
- In a clone, :func:`piezo_fmu_harness.fmus.path` finds the repository's FMUs, and ``$PIEZO_FMU``
  still overrides the harness's default.

The fresh environment is the honest proof that the wheel declares everything it needs: it does not
see the project's own environment (no ``--system-site-packages``), so a missing dependency or a
missing data file fails the test. It is the slow part of this file: about 13 s to make the
environment and install into it (pip takes numpy, scipy, matplotlib, dask and the rest from its
local wheels and cache), 4 s to build, 20 s for the whole file on the 2-core machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

import piezo_fmu
from piezo_fmu_harness import fmus
from piezo_fmu_harness.fmu import FMU_ENV, default_fmu_path

ROOT = Path(__file__).resolve().parent.parent
FMUS = {2: ROOT / "fmus" / "PiezoImpactDamper.fmu", 3: ROOT / "fmus" / "PiezoImpactDamper3.fmu"}


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> dict[str, Path]:
    """The sdist and the wheel ``python -m build`` makes from this clone."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)], check=True,
                   capture_output=True, text=True)
    wheels, sdists = sorted(out.glob("*.whl")), sorted(out.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1, sorted(p.name for p in out.iterdir())
    return {"wheel": wheels[0], "sdist": sdists[0]}


@pytest.fixture(scope="module")
def fresh_env(dist, tmp_path_factory) -> Path:
    """A new virtual environment holding only the wheel and the dependencies it declares."""
    env = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(env)], check=True)
    subprocess.run([str(env / "bin" / "python"), "-m", "pip", "install", "--quiet", "--no-compile",
                    str(dist["wheel"])], check=True, capture_output=True, text=True)
    return env


def run_in(env: Path, cwd: Path, *argv: str) -> subprocess.CompletedProcess:
    """``argv`` with the environment's bin/ first on PATH, in ``cwd``, without $PIEZO_FMU."""
    environ = {key: value for key, value in os.environ.items() if key not in (FMU_ENV, "PYTHONPATH")}
    environ["PATH"] = f"{env / 'bin'}{os.pathsep}{environ.get('PATH', '')}"
    return subprocess.run(list(argv), cwd=cwd, env=environ, capture_output=True, text=True)


# -- the distributions -----------------------------------------------------------------------------

def test_build_makes_a_wheel_and_an_sdist_that_twine_accepts(dist):
    version = piezo_fmu.__version__
    assert dist["wheel"].name == f"piezo_fmu-{version}-py3-none-any.whl"
    assert dist["sdist"].name == f"piezo_fmu-{version}.tar.gz"
    checked = subprocess.run([sys.executable, "-m", "twine", "check", "--strict", str(dist["wheel"]),
                              str(dist["sdist"])], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert checked.stdout.count("PASSED") == 2, checked.stdout


def test_the_wheel_carries_the_committed_fmus_and_no_generic_top_level_name(dist):
    with zipfile.ZipFile(dist["wheel"]) as wheel:
        names = wheel.namelist()
        for version, committed in FMUS.items():
            packaged = f"piezo_fmu_harness/fmu_files/{committed.name}"
            assert wheel.read(packaged) == committed.read_bytes(), packaged
        top_level = {name.split("/")[0] for name in names if not name.split("/")[0].endswith(".dist-info")}
        assert top_level == {"piezo_fmu", "piezo_fmu_harness"}
        info = next(name for name in names if name.endswith(".dist-info/entry_points.txt"))
        assert "piezo-fmu = piezo_fmu_harness.cli:main" in wheel.read(info).decode()


def test_the_sdist_carries_what_a_wheel_is_built_from(dist):
    with tarfile.open(dist["sdist"]) as sdist:
        names = {name.split("/", 1)[1] for name in sdist.getnames() if "/" in name}
    assert {"LICENSE", "README.md", "pyproject.toml", "fmus/PiezoImpactDamper.fmu", "fmus/PiezoImpactDamper3.fmu",
            "src/piezo_fmu/build/loader/loader.c", "src/piezo_fmu/build/loader/platform.h",
            "src/piezo_fmu/build/loader/platform_posix.c", "src/piezo_fmu/build/loader/platform_windows.c",
            "src/piezo_fmu/build/loader/manifest.json", "src/piezo_fmu_harness/fmus.py"} <= names


# -- the wheel in a fresh environment --------------------------------------------------------------

def test_the_installed_wheel_runs_the_nominal_case_from_any_directory(fresh_env, tmp_path):
    done = run_in(fresh_env, tmp_path, "piezo-fmu", "nominal", "--stop-time", "0.2")
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((tmp_path / "results" / "nominal" / "summary.json").read_text())
    assert summary["duration_s"] == 0.2
    site = run_in(fresh_env, tmp_path, "python", "-c", "import sysconfig; print(sysconfig.get_path('purelib'))")
    packaged = Path(site.stdout.strip()) / "piezo_fmu_harness" / "fmu_files" / "PiezoImpactDamper.fmu"
    assert summary["fmu"]["path"] == str(packaged)
    assert {p.name for p in (tmp_path / "results" / "nominal").iterdir()} >= {
        "timeseries.csv", "summary.json", "fig3a.png", "fig3b.png"}


def test_no_generic_harness_module_after_installing_the_wheel(fresh_env, tmp_path):
    done = run_in(fresh_env, tmp_path, "python", "-c", "import harness")
    assert done.returncode != 0
    assert "ModuleNotFoundError: No module named 'harness'" in done.stderr


def test_the_installed_package_finds_both_fmus_and_knows_its_version(fresh_env, tmp_path):
    code = ("import importlib.metadata, piezo_fmu\nfrom piezo_fmu_harness import fmus\n"
            "print(fmus.path(), fmus.path(fmi_version=3), piezo_fmu.__version__, "
            "importlib.metadata.version('piezo-fmu'))")
    done = run_in(fresh_env, tmp_path, "python", "-c", code)
    assert done.returncode == 0, done.stderr
    fmu2, fmu3, version, metadata = done.stdout.split()
    assert Path(fmu2).read_bytes() == FMUS[2].read_bytes() and Path(fmu3).read_bytes() == FMUS[3].read_bytes()
    assert fresh_env.resolve() in Path(fmu2).resolve().parents
    assert version == metadata == piezo_fmu.__version__


# -- in a clone ------------------------------------------------------------------------------------

def test_in_a_clone_the_fmus_are_the_repository_s():
    assert fmus.path() == FMUS[2] and fmus.path(fmi_version=3) == FMUS[3]


def test_an_fmi_version_other_than_2_or_3_is_refused_with_the_allowed_values():
    with pytest.raises(ValueError, match=r"fmi_version = 1 .*allowed values \[2, 3\]"):
        fmus.path(fmi_version=1)


def test_piezo_fmu_overrides_the_installed_fmu(monkeypatch, tmp_path):
    monkeypatch.delenv(FMU_ENV, raising=False)
    assert default_fmu_path() == fmus.path(fmi_version=2)
    monkeypatch.setenv(FMU_ENV, str(tmp_path / "other.fmu"))
    assert default_fmu_path() == tmp_path / "other.fmu"
