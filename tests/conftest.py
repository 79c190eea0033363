"""Hypothesis profiles: ``ci`` (the default, 500 examples), ``long`` (10 000) and ``dev`` (50); an
instance of the FMI 2.0 FMU for the tests of the forced response (one per module); the standalone
FMUs, built once per content of their inputs (``piezo_fmu.build.standalone.cached``)."""

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
