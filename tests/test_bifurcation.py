"""The bifurcation diagram (issues 23, 27): section samples and impacts per cycle, up and down, on the
batch engine, every motion that does not settle classified, a sample of points checked through the
FMU; bad input refused before any run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fmu_host import assert_refused, run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.studies.bifurcation.study import CLASSES

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"


@pytest.fixture(scope="module")
def diagram(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bifurcation")
    assert run_cli("bifurcation", "--ratio-min", 0.98, "--ratio-max", 1.02, "--count", 3, "--jobs", 2, "--out", out,
                   "--fmu", FMU) == 0
    return out


def test_each_point_has_its_section_samples_and_its_class(diagram):
    ds = open_dataset(diagram / "bifurcation.nc")
    assert ds.sizes["direction"] == 2 and ds.sizes["omega"] == 3
    motion = ds["motion"].values
    assert set(np.unique(motion)) <= set(CLASSES)
    samples = np.isfinite(ds["p_section"].values).sum(axis=-1)
    for where in np.ndindex(motion.shape):
        if motion[where] == "periodic":
            assert 1 <= samples[where] <= 4  # an orbit of order n gives its n samples
            assert np.isnan(ds["lyapunov_exponent"].values[where])
        else:
            assert samples[where] == 40
            # An exponent, unless the impact mass was in contact at every section (chatter).
            assert np.isfinite(ds["lyapunov_exponent"].values[where]) == (motion[where] != "unclassified")
    # At w_n the default damper's motion is chaotic, sweeping either way (see tests/test_motion.py).
    assert (ds["motion"].sel(omega=ds["omega"].values[1]).values == "chaotic").all()
    summary = json.loads((diagram / "summary.json").read_text())
    assert sum(c["count"] for d in summary["classes"].values() for c in d.values()) == 6
    assert (diagram / "bifurcation.png").stat().st_size > 0


def test_the_fmu_checked_every_kind_of_motion_the_diagram_shows_and_none_disagreed(diagram):
    summary = json.loads((diagram / "summary.json").read_text())
    checks = summary["fmu_checks"]
    assert checks["disagree"] == 0 and checks["agree"] + checks["parted"] == checks["checked"]
    shown = {kind for classes in summary["classes"].values() for kind in classes}
    assert {c["motion"] for c in checks["points"] if c["verdict"] == "agrees"} == shown


@pytest.mark.parametrize("argv, words", [
    (["--ratio-min", "0"], ["--ratio-min 0", "allowed range (0, inf)"]),
    (["--ratio-min", "1.2", "--ratio-max", "1.1"], ["--ratio-min 1.2", "reversed range"]),
    (["--count", "1"], ["--count 1", "allowed range [2, inf)"]),
    (["--set", "m=-1"], ["m = -1.0 is not above 0", "allowed range (0, inf] kg"]),
    (["--confirm", "-1"], ["--confirm -1", "allowed range [0, inf)"]),
    (["--device", "gpu"], ["--device gpu", "numba", "GPU"]),
])
def test_bad_bifurcation_input_is_refused_with_exit_status_2(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert_refused(capsys, "bifurcation", argv, words, "--out", out, "--fmu", FMU)
    assert not (out / "bifurcation.nc").exists()
