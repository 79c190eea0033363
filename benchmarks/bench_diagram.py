"""Where the bifurcation diagram's time goes: its sweeps in one process on one thread,
the compiled kernel's time apart from the Python between its blocks.

    python benchmarks/bench_diagram.py [--count N] [--max-cycles N] [--out DIR] [--fmu FILE] [--bare]

Runs ``piezo-fmu bifurcation --jobs 1`` (the default diagram unless ``--count`` or
``--max-cycles`` say otherwise) with ``NUMBA_NUM_THREADS=1``, without the FMU's checks (they come
after the sweeps and are not what ``--jobs`` shares out), and times every launch of the kernel and
the pieces of ``settle`` that run between two blocks of marching. The run is the diagram itself:
the same ``points.json`` as without the timers (the test checks it). The batch engine is the
FMU's copy (as for the command): ``--fmu`` names another build, to compare two side by side.

Prints one JSON object: ``sweeps_s`` (the sweeps' wall, as ``summary.json``'s ``marching_s``),
``kernel_s`` (every launch of the kernel: the marching, and Newton's, the checks' and the
measures' small ensembles), ``rest_s`` (the rest), ``kernel_share``, ``pieces`` (each piece's own
Python, its kernel launches left out: Newton, the verification and the multipliers of the orbits
it finds, the screen for Newton's seeds, the proofs of free flight, the labelling on known orbits,
the history, the measures of the points on no orbit) with ``other_s`` (settle's set-up, the
survival fits, the tasks' own, the timers'), ``calls`` and ``start_periods``; and
``floor_2_cores_s``: the kernel's time shared by two cores, the sweeps' wall on two cores were
everything else free. ``--bare`` runs the diagram without the timers and prints ``sweeps_s`` and
``start_periods`` only. Exits 2, with the command's message, on a bad option.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path

#: The pieces of ``settle`` timed (module, function), the kernel launches inside each left out.
PIECES = (("attractors.orbits", "OrbitFinder.newton"), ("attractors.orbits", "OrbitFinder.verify"),
          ("attractors.orbits", "OrbitFinder.multipliers"), ("attractors.settle", "_find_orbits"),
          ("attractors.settle", "_label_quiet"), ("attractors.settle", "_label_orbits"),
          ("attractors.settle", "_extend"), ("attractors.settle", "measure"))
#: Pieces that call other pieces: their own time is theirs less their callees'.
CALLEES = {"_find_orbits": ("newton", "verify", "multipliers")}


class Timers:
    """Seconds and calls of the kernel's launches and of each piece, the kernel's launches
    inside a piece counted apart."""

    def __init__(self):
        self.seconds: dict = {}
        self.calls: dict = {}
        self.inside: list = []

    def add(self, name: str, seconds: float) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + seconds
        self.calls[name] = self.calls.get(name, 0) + 1

    def wrap(self, function, name: str):
        def timed(*args, **kwargs):
            self.inside.append(name)
            begin = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.add(name, time.perf_counter() - begin)
                self.inside.pop()
        return timed

    def wrap_kernel(self, launch):
        def timed(*args, **kwargs):
            begin = time.perf_counter()
            try:
                return launch(*args, **kwargs)
            finally:
                # the innermost piece that is not a caller of others owns the launch
                owner = next((name for name in reversed(self.inside) if name not in CALLEES), None)
                self.add("kernel" if owner is None else f"kernel in {owner}", time.perf_counter() - begin)
        return timed


def instrument(timers: Timers) -> None:
    """Put the timers on the batch engine the diagram runs (the FMU's copy of ``piezo_fmu``, once
    the command has loaded it)."""
    from piezo_fmu.solver.batch import kernel
    kernel._launch = timers.wrap_kernel(kernel._launch)
    for module_name, qualified in PIECES:
        module = importlib.import_module(f"piezo_fmu.solver.batch.{module_name}")
        owner, _, name = qualified.rpartition(".")
        holder = getattr(module, owner) if owner else module
        setattr(holder, name, timers.wrap(getattr(holder, name), name))


def measure(count: int | None, max_cycles: int | None, out: Path, timed: bool = True, fmu: Path | None = None) -> dict:
    """The diagram's sweeps, timed (see the module's text); ``timed`` False runs it bare."""
    from piezo_fmu_harness.cli import main
    from piezo_fmu_harness.studies.bifurcation import chains

    timers = Timers()
    run = chains.run

    def instrumented_run(*args, **kwargs):
        from piezo_fmu.solver.batch import kernel
        kernel.target("cpu")  # the compiled code loaded before the sweeps' clock starts, timed or bare
        if timed:
            instrument(timers)
        return run(*args, **kwargs)

    chains.run, checks = instrumented_run, chains.checks
    chains.checks = lambda *args, **kwargs: []  # the FMU's checks come after the sweeps
    argv = ["bifurcation", "--jobs", "1", "--out", str(out), "--force", "--no-progress"]
    argv += [] if count is None else ["--count", str(count)]
    argv += [] if max_cycles is None else ["--max-cycles", str(max_cycles)]
    argv += [] if fmu is None else ["--fmu", str(fmu)]
    try:
        with contextlib.redirect_stdout(sys.stderr):  # the command's lines; stdout is the JSON's
            code = main(argv)
    finally:
        chains.run, chains.checks = run, checks
    if code != 0:
        raise SystemExit(code)
    summary = json.loads((out / "summary.json").read_text())
    if not timed:
        return {"sweeps_s": summary["marching_s"], "start_periods": summary["start_periods"]}
    return report(timers, summary)


def report(timers: Timers, summary: dict) -> dict:
    seconds, sweeps = timers.seconds, summary["marching_s"]
    kernel = sum(v for k, v in seconds.items() if k.startswith("kernel"))
    own = {}
    for _, qualified in PIECES:
        name = qualified.rpartition(".")[2]
        callees = CALLEES.get(name, ())
        own[name] = (seconds.get(name, 0.0) - seconds.get(f"kernel in {name}", 0.0)
                     - sum(seconds.get(c, 0.0) for c in callees))
    rest = sweeps - kernel
    return {"sweeps_s": sweeps, "kernel_s": kernel, "rest_s": rest, "kernel_share": kernel / sweeps,
            "kernel_by_owner_s": {k: v for k, v in seconds.items() if k.startswith("kernel")},
            "pieces": {**own, "other_s": rest - sum(own.values())},
            "calls": {k: v for k, v in timers.calls.items() if not k.startswith("kernel in")},
            "start_periods": summary["start_periods"], "floor_2_cores_s": kernel / 2.0}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, help="frequencies a sweep (the command's default: 200)")
    parser.add_argument("--max-cycles", type=int, help="the budget of periods (the command's default: 1000)")
    parser.add_argument("--out", type=Path, help="where the diagram's files go (default: a temporary folder)")
    parser.add_argument("--fmu", type=Path, help="the FMI 2.0 FMU whose copy of the batch engine marches (default: the "
                                                 "installed one): two builds compared side by side")
    parser.add_argument("--bare", action="store_true", help="the diagram without the timers: their cost, by comparison")
    args = parser.parse_args(argv)
    if os.environ.get("NUMBA_NUM_THREADS", "1") != "1":
        parser.error(f"NUMBA_NUM_THREADS = {os.environ['NUMBA_NUM_THREADS']!r}: the diagram is measured on one "
                     "thread (a worker's share of 2 cores under --jobs 2); allowed: unset or '1'")
    os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported: one thread, as a worker of --jobs 2
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", file=sys.stderr)
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch) / "diagram"
        result = measure(args.count, args.max_cycles, out, timed=not args.bare, fmu=args.fmu)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
