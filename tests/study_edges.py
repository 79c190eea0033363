"""Dampers drawn over the FMU's declared ranges, and the batch studies run on them from the CLI's
entry point with every warning an error (``test_study_limits.py``; a wider exploration by hand:
``python tests/study_edges.py SEED COUNT``, one JSON line a damper).

A damper is the nominal one with one to three of its parameters drawn log-uniformly over the whole
range the FMU declares for each (``parameter_info``'s bounds: from the smallest positive double, or
0 where 0 is allowed, to the largest double; either end a tenth of the time each), the barrier's
equivalents given explicitly a third of the time, and the voltage model and the load drawn too now
and then. Drawing every parameter at once would give dampers the FMU refuses nearly always (a patch
past the beam's end, a main mass lighter than the barrier's tip mass): few would reach the batch
engine.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time

import numpy as np

from piezo_fmu.model.parameters import parameter_info

#: The smallest positive and the largest double: the ends of an open range ``(0, inf)``.
TINY, HUGE = 5e-324, sys.float_info.max
#: What is not drawn: the initial state (the studies set it), the integer choices (drawn apart),
#: and the load (drawn as ``--load``).
NOT_DRAWN = ("p0", "q0", "dp0", "dq0", "barrier_mode", "voltage_model", "R_load")
#: Each study at its smallest size, the FMU's checks only one start of each attractor (one realization
#: of the random study), in this process.
PERIODIC = ["--max-cycles", "10", "--confirm", "0"]
SMALLEST = {"basins": ["--ratio", "1.2", "--grid", "2", *PERIODIC],
            "fractions": ["--count", "2", "--starts", "1", *PERIODIC],
            "bifurcation": ["--count", "2", *PERIODIC],
            "random": ["--realizations", "2", "--duration", "1", "--confirm", "1"]}
COMMON = ["--jobs", "1", "--no-progress", "--force"]


def draw_value(rng, bound) -> float:
    """A value of ``bound`` (a :class:`~piezo_fmu.model.parameters.Bound`), log-uniform over it, its
    ends a tenth of the time each (a finite range's magnitude, with either sign)."""
    signed = bound.lo == -math.inf
    lo = TINY if signed or (bound.lo == 0.0 and bound.lo_open) else bound.lo
    hi = min(bound.hi, HUGE)
    u = rng.random()
    magnitude = lo if u < 0.1 else hi if u < 0.2 else math.exp(rng.uniform(math.log(max(lo, TINY)), math.log(hi)))
    return float(rng.choice([-1.0, 1.0])) * magnitude if signed else magnitude


def draw_damper(rng) -> tuple[dict, list[str]]:
    """``(values, options)``: ``--set`` values and the load's and voltage model's options."""
    info = parameter_info()
    names = sorted(name for name in info if name not in NOT_DRAWN)
    count = 1 if rng.random() < 0.6 else int(rng.integers(2, 4))
    values = {str(name): draw_value(rng, info[name]["bound"]) for name in rng.choice(names, count, replace=False)}
    if rng.random() < 1 / 3:
        values["barrier_mode"] = 1
    options = []
    if rng.random() < 0.3:
        options += ["--voltage-model", str(int(rng.integers(0, 3)))]
    if rng.random() < 0.2:
        options += ["--load", repr(draw_value(rng, info["R_load"]["bound"]))]
    return values, options


def study_runs(values: dict, options: list[str], out, studies=tuple(SMALLEST)) -> list[list[str]]:
    """The argument lists of the batch ``studies`` on the damper ``values``, results under ``out``.
    The random study takes voltage models 0 and 2 only (it refuses 1 by its option's name): it is
    marched with its default, 2, where 1 was drawn."""
    sets = [text for name, value in values.items() for text in ("--set", f"{name}={value!r}")]
    pairs = list(zip(options[::2], options[1::2]))
    runs = []
    for study in studies:
        extra = [text for pair in pairs if study != "random" or pair != ("--voltage-model", "1") for text in pair]
        runs.append([study, *SMALLEST[study], *sets, *extra, *COMMON, "--out", f"{out}/{study}"])
    return runs


CHILD = r"""
import contextlib, io, json, sys, time, traceback, warnings
warnings.simplefilter("error")
from piezo_fmu_harness import cli
for argv in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    begin = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code, kind = cli.main(argv), "returned"
    except SystemExit as exit_:
        code, kind = exit_.code, "exited"
    except BaseException:
        code, kind = None, "raised"
        err.write(traceback.format_exc())
    print(json.dumps({"argv": argv, "code": code, "kind": kind, "stdout": out.getvalue(), "stderr": err.getvalue(),
                      "seconds": time.perf_counter() - begin}), flush=True)
"""


def run_studies(runs: list[list[str]], timeout: float) -> tuple[int, list[dict], str]:
    """The studies ``runs`` in one child process with every warning an error: its exit status
    (negative for a signal), one record a run and its own stderr."""
    done = subprocess.run([sys.executable, "-W", "error", "-c", CHILD, json.dumps(runs)], capture_output=True,
                          text=True, timeout=timeout)
    return done.returncode, [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")], done.stderr


if __name__ == "__main__":  # the wider exploration: python tests/study_edges.py SEED COUNT > runs.jsonl
    import tempfile

    seed, count = int(sys.argv[1]), int(sys.argv[2])
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as folder:
        for k in range(count):
            values, options = draw_damper(rng)
            begin = time.perf_counter()
            try:
                status, records, stderr = run_studies(study_runs(values, options, f"{folder}/{k}"), 600)
            except subprocess.TimeoutExpired:
                status, records, stderr = "timeout", [], ""
            print(json.dumps({"k": k, "values": values, "options": options, "status": status, "runs": records,
                              "stderr": stderr[-3000:], "seconds": time.perf_counter() - begin}),
                  flush=True)
