"""Hypothesis profiles: ``ci`` (the default, 500 examples), ``long`` (10 000) and ``dev`` (50); an
instance of the FMI 2.0 FMU for the tests of the forced response (one per module)."""

import os
from pathlib import Path

import pytest
from hypothesis import settings

from piezo_fmu_harness.fmu import FmuModel, Instance, discard

FMU = Path(__file__).resolve().parent.parent / "fmus" / "PiezoImpactDamper.fmu"

settings.register_profile("ci", max_examples=500, derandomize=True, print_blob=True)
settings.register_profile("long", max_examples=10_000, print_blob=True)
settings.register_profile("dev", max_examples=50, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(scope="module")
def instance():
    """An instance of the committed FMI 2.0 FMU, freed with its folder after the module."""
    model = FmuModel(FMU)
    unzipdir = model.extract()
    yield Instance(model, unzipdir)
    discard(unzipdir)
