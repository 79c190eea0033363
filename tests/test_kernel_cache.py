"""Where the compiled kernel is kept (:mod:`piezo_fmu.solver.batch.kernel.cache`): a copy of the
package (an FMU's) finds the code another compiled, each version of the batch engine's files has its
own folder, and a folder that cannot be written costs a compilation, not the study."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from piezo_fmu import Parameters
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, kernel

ROOT = Path(__file__).resolve().parents[1]
W_N = 1000.0 ** 0.5
NOMINAL = Parameters(voltage_model=1, R_load=3.59e6)


def test_a_copy_of_the_package_finds_the_compiled_kernel_in_the_cache(tmp_path):
    """A process that imports ``piezo_fmu`` from another folder (an FMU's unpacked copy) loads the
    kernel that this one compiled instead of compiling it again."""
    Ensemble(NOMINAL, HarmonicHold(W_N, 1e-3), [(0.0, 0.0, 0.0, 0.0)]).advance(1)  # compiled or loaded
    copy = tmp_path / "resources"
    shutil.copytree(ROOT / "src" / "piezo_fmu", copy / "piezo_fmu", ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import piezo_fmu, numpy as np\n"
            "from piezo_fmu import Parameters\n"
            "from piezo_fmu.solver.batch import Ensemble, HarmonicHold\n"
            "assert piezo_fmu.__file__.startswith(%r), piezo_fmu.__file__\n"
            "Ensemble(Parameters(), HarmonicHold(31.6, 1e-3), [(0.0, 0.0, 0.0, 0.0)]).advance(1)\n" % str(copy))
    env = dict(os.environ, NUMBA_DEBUG_CACHE="1", PYTHONPATH=str(copy))
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600,
                            cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    log = result.stdout + result.stderr
    assert "data loaded" in log
    assert "data saved" not in log, log[-3000:]


def test_each_version_of_the_batch_engines_files_has_its_own_cache_folder(tmp_path):
    """The compiled code is kept by the content of all the engine's files: a copy elsewhere finds the
    same folder; a change to any one of them (the entry points' file, or one whose functions the
    kernel only calls) another."""
    from piezo_fmu.solver.batch.kernel import cache

    copies = []
    for name in ("a", "b", "c"):
        copies.append(tmp_path / name / "batch")
        shutil.copytree(cache.PACKAGE, copies[-1], ignore=shutil.ignore_patterns("__pycache__"))
    here = cache.version_folder(tmp_path, cache.PACKAGE)
    assert cache.version_folder(tmp_path, copies[0]) == here
    cpu = copies[1] / "kernel" / "cpu.py"
    cpu.write_text(cpu.read_text() + "\n# another compiler option\n")
    assert cache.version_folder(tmp_path, copies[1]) != here
    (copies[2] / "kernel" / "switches.py").rename(copies[2] / "kernel" / "rules.py")  # the same bytes, moved
    assert cache.version_folder(tmp_path, copies[2]) not in (here, cache.version_folder(tmp_path, copies[1]))
    assert here.parent == tmp_path


def test_a_cache_folder_that_cannot_be_written_costs_a_compilation_not_the_study(tmp_path):
    """``NUMBA_CACHE_DIR`` under a file, where no folder can be made (a home that is not the user's,
    a read-only container): numba alone refuses to compile a cached function it has nowhere to keep
    ("no locator available"). The kernel is compiled for the process alone, a warning says so, where
    and what to set, nothing is written, and the march is the cached kernel's, bit for bit."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    starts = [(0.0, 0.2, 3e-3, 0.0), (2e-3, 0.0, 2e-3, 0.0)]
    here = Ensemble(NOMINAL, HarmonicHold(1.2 * W_N, 1e-3), starts).advance(5, observe=True)
    code = ("import json, math\n"
            "from piezo_fmu import Parameters\n"
            "from piezo_fmu.solver.batch import Ensemble, HarmonicHold\n"
            "r = Ensemble(Parameters(voltage_model=1, R_load=3.59e6), HarmonicHold(1.2 * math.sqrt(1000.0), 1e-3),\n"
            "             %r).advance(5, observe=True)\n"
            "print(json.dumps({k: v.tolist() for k, v in r.items()}))\n" % (starts,))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(blocker / "cache"))
    before = sorted(ROOT.rglob("*.nbi"))
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600,
                            cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "the compiled kernel cannot be kept in" in result.stderr and str(blocker / "cache") in result.stderr
    assert "NUMBA_CACHE_DIR" in result.stderr
    there = json.loads(result.stdout)
    assert set(there) == set(here)
    for name, values in here.items():
        assert np.array_equal(np.asarray(there[name], dtype=values.dtype), values, equal_nan=True), name
    assert here["impacts"].sum() > 0
    assert sorted(ROOT.rglob("*.nbi")) == before
