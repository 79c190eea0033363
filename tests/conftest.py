"""Hypothesis profiles: ``ci`` (the default, 500 examples), ``long`` (10 000) and ``dev`` (50); an
instance of the FMI 2.0 FMU for the tests of the forced response (one per module); the standalone
FMUs, built once per content of their inputs (``piezo_fmu.build.standalone.cached``).

``make test`` runs the suite on every core (pytest-xdist): each test file is one group, run by
one worker (its module fixtures are made once), and the files that share the Wine prefix and the
standalone FMUs' cache in ``~/.cache/piezo-fmu`` are one group between them, so that no two
workers fill that cache at once. The longest groups go first."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

from piezo_fmu_harness.fmu import FmuModel, Instance, discard

FMU = Path(__file__).resolve().parent.parent / "fmus" / "PiezoImpactDamper.fmu"

settings.register_profile("ci", max_examples=500, derandomize=True, print_blob=True)
settings.register_profile("long", max_examples=10_000, print_blob=True)
settings.register_profile("dev", max_examples=50, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


#: Test files that share the Wine prefix and the standalone FMUs' cache: one group.
SHARED_CACHE = ("test_windows.py", "test_standalone.py", "test_standalone_windows.py")
#: The groups that take longest (seconds on 2 cores, ``--durations``), handed out first so that no
#: worker is left with a long one at the end.
LONGEST = ("test_fractions.py", "wine", "test_optimize.py", "test_stability.py", "test_bifurcation.py",
           "test_masri_caughey.py", "test_frequency_response.py", "test_continuation.py", "test_resume.py",
           "test_packaging.py")


def group_of(path: Path) -> str:
    return "wine" if path.name in SHARED_CACHE else path.name


def pytest_collection_modifyitems(config, items):
    rank = {name: k for k, name in enumerate(LONGEST)}
    items.sort(key=lambda item: rank.get(group_of(item.path), len(LONGEST)))  # stable: files keep their order


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's scheduler with the groups of :func:`group_of`, handed out in the order of
    the collection (the longest first). Its own ``xdist_group`` marks cannot do it here: from
    pytest 9.2 on, pytest-xdist 3.8 cannot add a group to a test's node id, so every marked test
    would be scheduled alone."""
    from xdist.scheduler import LoadScopeScheduling

    class FileGroups(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(Path(nodeid.split("::", 1)[0]))

    config.option.loadscopereorder = False
    return FileGroups(config, log)


@pytest.fixture(scope="session")
def standalone_fmus() -> dict:
    """The standalone FMU of each FMI version (2, 3), from the current sources. Built in a child
    process: the build imports pythonfmu, which in this process may already be an FMU's copy."""
    code = ("from piezo_fmu.build import fmus, standalone\n"
            "for version, target in sorted(fmus.TARGETS.items()): print(version, standalone.cached(target))")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stderr
    return {int(version): Path(path) for version, path in (line.split(" ", 1) for line in completed.stdout.splitlines())}


@pytest.fixture(scope="module")
def instance():
    """An instance of the committed FMI 2.0 FMU, freed with its folder after the module."""
    model = FmuModel(FMU)
    unzipdir = model.extract()
    yield Instance(model, unzipdir)
    discard(unzipdir)
