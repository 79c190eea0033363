"""Where the compiled kernel is kept (:mod:`piezo_fmu.solver.batch.kernel.cache`): a copy of the
package (an FMU's) finds the code another compiled, each version of the batch engine's files has its
own folder, processes that start on an empty cache at once take turns and march the same bits, and
a folder that cannot be written costs a compilation, not the study."""

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


#: A march through every compiled entry point a study uses (the march, the Lyapunov pair, settle's
#: bookkeeping), printing a digest of every output.
EVERY_ENTRY = """
import hashlib, math
import numpy as np
from piezo_fmu import Parameters
from piezo_fmu.solver.batch import Ensemble, HarmonicHold, SettleSettings, settle
rng = np.random.default_rng(0)
w, d = 1.2 * math.sqrt(1000.0), 8e-3
p = rng.uniform(-d, d, 24)
starts = np.column_stack([p, rng.uniform(-d * w, d * w, 24), p + rng.uniform(-d / 2, d / 2, 24), np.zeros(24)])
params, drive = Parameters(voltage_model=2, R_load=3.59e6), HarmonicHold(w, 1e-3)
marched = Ensemble(params, drive, starts).advance(10, observe=True)
pair = Ensemble(params, drive, starts[:4]).separate(np.full((4, 4), 1e-9), np.ones((4, 4)), np.full(4, 1e-9), 4)
done = settle(params, drive, starts[:12], settings=SettleSettings(max_cycles=120))
digest = hashlib.sha256()
for array in (marched["sections"], marched["top"], marched["impacts"], pair["logs"], done.labels, done.final):
    digest.update(np.ascontiguousarray(array).tobytes())
print(digest.hexdigest())
"""


def test_four_processes_that_compile_into_an_empty_cache_at_once_take_turns_and_march_the_same_bits(tmp_path):
    """Four processes started together on an empty ``NUMBA_CACHE_DIR`` (a Dask cluster's workers at
    their first task): every one finishes, with the bits of this process's kernel, and each piece of
    compiled code is saved once, by whichever process reached its entry point first, the others load
    it (the first call of each entry point holds the cache folder's lock). Without the lock each
    process saves its own compilation into the same index (20 to 22 saves in every process), and a
    version number may come to point at another process's code."""
    here = subprocess.run([sys.executable, "-c", EVERY_ENTRY], capture_output=True, text=True, timeout=900,
                          cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT / "src")))
    assert here.returncode == 0, here.stderr[-3000:]
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_DEBUG_CACHE="1",
               PYTHONPATH=str(ROOT / "src"))
    processes = [subprocess.Popen([sys.executable, "-c", EVERY_ENTRY], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, env=env, cwd=tmp_path) for _ in range(4)]
    outputs = [process.communicate(timeout=900) for process in processes]
    assert [process.returncode for process in processes] == [0, 0, 0, 0], [err[-2000:] for _, err in outputs]
    digests = [out.strip().splitlines()[-1] for out, _ in outputs]
    assert digests == [here.stdout.strip().splitlines()[-1]] * 4
    saved = [line.split("data saved to", 1)[1].strip() for out, _ in outputs for line in out.splitlines()
             if "data saved to" in line]
    assert len(saved) > 10 and len(set(saved)) == len(saved), sorted(saved)  # each compiled once, by one process
