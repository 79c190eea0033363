"""What the compiled kernel's event searches cost: the kernel against itself with every
evaluation its searches make done twice, side by side in one run.

    python benchmarks/bench_searches.py [--ratios R,R,...] [--starts N] [--transient P] [--periods P] [--rounds K]
                                        [--points DIAGRAM/points.json] [--cache DIR]

A search for a contact onset or a separation steps towards the event (``kernel.location.locate``):
at each step it evaluates the event functions, free flight's closed form (an ``exp`` and a
``sincos``) or the contact's modes (an ``exp`` and a ``sincos`` a mode), and computes the next step
(``safe_step``: a square root and a few operations for each function). Four versions of the kernel
march the same starts: the kernel as it is, and the kernel whose searches do one of these twice at
every step: evaluate the contact's modes (``contact``), evaluate free flight (``free``), compute the
step (``steps``). The second is made after the first (through ``+ 0 x`` its values), so the
compiler can neither drop it nor run both at once, and its result replaces the first: the motion is
the same bit for bit (``same_bits`` says so). The time a version adds is what that work costs; the
sum of the three is what the searches' work costs, bar their loop's own branches: the most another
event location could save, were its searches to cost nothing at all.

Each version runs in a process of its own, with a numba cache of its own in a temporary folder
(the versions differ in code that numba's cache does not tell apart; ``--cache DIR`` keeps them
there, a folder a version, for the next run), the processes in turn,
``--rounds`` times; each figure is the median over the rounds of the fastest of three marches a
process. The starts: ``--starts`` random starts (``bench_gpu.starts``) at each ratio to
``sqrt(K/M)``, or with ``--points`` the cloud of a bifurcation diagram's chaotic point nearest each
ratio (its start and up to ``--starts - 1`` companions, made as the diagram makes them: ``piezo-fmu
bifurcation`` writes ``points.json``), marched ``--transient`` periods first, then timed over
``--periods``, one thread (``NUMBA_NUM_THREADS=1``), unobserved, as the studies march them.

Prints one JSON object: the functions each version's searches call (``searches``); for each ratio,
ns a start-period of each version, the share each doubled piece adds (``contact_share``,
``free_share``, ``steps_share``), their sum (``searches_share``, the bound above), ``same_bits``
and the contact onsets a period. Exits 1 when a version's motion differs from the kernel's.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # bench_gpu's starts and damper, shared with bench_batch.py
VERSIONS = ("kernel", "contact", "free", "steps")
#: The frequencies measured: chaotic motion at 0.877 and 1.0 (about 3 impacts a period), 0.553 and
#: 1.48 (about 2 and 1.5), and 1.9 (one impact every other period).
RATIOS = (0.553, 0.877, 1.0, 1.48, 1.9)


#: The kernel's own functions, which a doubled version calls twice, and numpy's minimum (set by
#: :func:`patch`).
contact_value_once = free_values_once = safe_step_once = fmin = None


def contact_twice(s, c, work, t):
    """``contact_value`` evaluated twice, the second time at the same instant after the first."""
    g, dg = contact_value_once(s, c, work, t)
    return contact_value_once(s, c, work, t + 0.0 * (g + dg))


def free_twice(c, work, phase, t):
    """``free_values`` evaluated twice, the second time at the same instant after the first."""
    g_a, g_b, dg_a, dg_b, tol = free_values_once(c, work, phase, t)
    return free_values_once(c, work, phase, t + 0.0 * (g_a + g_b + dg_a + dg_b + tol))


def steps_twice(g, dg, bound):
    """``safe_step`` computed twice, the second time after the first (through ``dg``, whose zero's
    sign the step does not read)."""
    step = safe_step_once(g, dg, bound)
    return safe_step_once(g, dg + 0.0 * fmin(abs(step), 1.0), bound)


#: The names, in the kernel's searches (:mod:`piezo_fmu.solver.batch.kernel.location`), of the
#: pieces a version doubles.
SEARCHES = ("contact_value", "free_values", "safe_step")


def patch(version: str) -> None:
    """Make the kernel this process compiles the ``version`` (before its first compilation): the
    searches call the doubled piece, registered as the kernel's own is (compiled into its callers
    when it is)."""
    from piezo_fmu.solver.batch.kernel import location, registry

    global fmin
    fmin = location.fmin
    if version == "kernel":
        return
    name, twice = {"contact": ("contact_value", contact_twice), "free": ("free_values", free_twice),
                   "steps": ("safe_step", steps_twice)}[version]
    own = getattr(location, name)
    globals()[name + "_once"] = own
    registry.source(twice, inline=registry._KINDS[own] == "inline")
    setattr(location, name, twice)


def workload(ratio: float, count: int, points: str | None) -> tuple:
    """``(params, drive, starts, sides)`` at ``ratio``: random starts, or the cloud of the chaotic
    point of a bifurcation diagram's ``points.json`` nearest to ``ratio``."""
    from bench_gpu import VALUES, W_N, Y, starts

    from piezo_fmu import Parameters
    from piezo_fmu.solver.batch import HarmonicHold

    if points is None:
        omega = ratio * W_N
        return Parameters(**VALUES), HarmonicHold(omega, Y), starts(count, omega), None
    from piezo_fmu_harness.studies.bifurcation.study import cloud

    diagram = json.loads(Path(points).read_text())
    chaotic = [p for sweep in diagram["sweeps"] for p in sweep["points"] if p["motion"] == "chaotic"]
    if not chaotic:
        raise SystemExit(f"bench_searches: --points {points}: no chaotic point")
    point = min(chaotic, key=lambda p: abs(p["ratio"] - ratio))
    states = np.vstack([point["start"], cloud(point["start"], point["omega"], point["amplitude_Y"], 0)])[:count]
    return (Parameters(**diagram["values"]), HarmonicHold(point["omega"], point["amplitude_Y"]), states,
            [point["start_side"]] * len(states))


def child(version: str, ratios: list, count: int, transient: int, periods: int, points: str | None) -> dict:
    """Marches of the ``version`` at each ratio, in this process (see the module's text)."""
    patch(version)
    from piezo_fmu.solver.batch import Ensemble

    from piezo_fmu.solver.batch.kernel import location

    out = {"searches": [getattr(location, name).__name__ for name in SEARCHES]}
    for ratio in ratios:
        params, drive, starts, sides = workload(ratio, count, points)
        ens = Ensemble(params, drive, starts, sides=sides)
        if transient:
            ens.advance(transient, observe=False)
        state, sides = ens.states, ens.sides
        times, digest, impacts = [], None, None
        for _ in range(3):
            again = Ensemble(params, drive, state, sides=sides)
            begin = time.perf_counter()
            marched = again.advance(periods, observe=False)
            times.append(time.perf_counter() - begin)
            digest = hashlib.sha256(marched["sections"].tobytes() + marched["impacts"].tobytes()).hexdigest()
            impacts = float(np.mean(marched["impacts"]))
        out[str(ratio)] = {"ns": 1e9 * min(times) / (count * periods), "digest": digest, "impacts": impacts}
    return out


def run_child(version: str, cache: Path, args) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache / version), NUMBA_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join([str(HERE.parent / "src"), env.get("PYTHONPATH", "")])
    command = [sys.executable, __file__, "--child", version, "--ratios", ",".join(map(str, args.ratios)),
               "--starts", str(args.starts), "--transient", str(args.transient), "--periods", str(args.periods)]
    if args.points:
        command += ["--points", args.points]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"bench_searches: the {version} version failed:\n{done.stderr}")
    return json.loads(done.stdout)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ratios", type=lambda text: [float(x) for x in text.split(",")], default=list(RATIOS))
    parser.add_argument("--starts", type=int, default=80)
    parser.add_argument("--transient", type=int, default=200)
    parser.add_argument("--periods", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--points", help="a bifurcation diagram's points.json: its chaotic points' clouds")
    parser.add_argument("--cache", help="a folder for the versions' numba caches, kept (default: a temporary one)")
    parser.add_argument("--child", choices=VERSIONS)
    args = parser.parse_args(argv)
    for name, value, least in (("--starts", args.starts, 1), ("--transient", args.transient, 0),
                               ("--periods", args.periods, 1), ("--rounds", args.rounds, 1)):
        if value < least:
            parser.error(f"{name} = {value} is out of range; allowed range [{least}, inf)")
    if not args.ratios or min(args.ratios) <= 0.0:
        parser.error(f"--ratios = {args.ratios} is out of range; allowed: one ratio or more, each in (0, inf)")
    if args.points and not Path(args.points).is_file():
        parser.error(f"--points = {args.points}: no such file; allowed: the points.json that piezo-fmu bifurcation writes")
    if args.child:
        print(json.dumps(child(args.child, args.ratios, args.starts, args.transient, args.periods, args.points)))
        return 0
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-searches-") as folder:
        cache = Path(args.cache) if args.cache else Path(folder)
        runs = [{version: run_child(version, cache, args) for version in VERSIONS} for _ in range(args.rounds)]
    result = {"load_average_before": load, "points": args.points, "starts": args.starts,
              "transient": args.transient, "periods": args.periods, "rounds": args.rounds,
              "searches": {version: runs[0][version]["searches"] for version in VERSIONS}, "ratios": {}}
    for ratio in map(str, args.ratios):
        ns = {version: float(np.median([run[version][ratio]["ns"] for run in runs])) for version in VERSIONS}
        digests = {run[version][ratio]["digest"] for run in runs for version in VERSIONS}
        contact, free, steps = (ns[v] / ns["kernel"] - 1.0 for v in ("contact", "free", "steps"))
        result["ratios"][ratio] = {"ns_per_start_period": ns, "contact_share": contact, "free_share": free,
                                   "steps_share": steps, "searches_share": contact + free + steps,
                                   "same_bits": len(digests) == 1,
                                   "impacts_per_period": runs[0]["kernel"][ratio]["impacts"]}
    print(json.dumps(result, indent=2))
    return 0 if all(r["same_bits"] for r in result["ratios"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
