"""Bit-level fingerprints of the core on six cases, to show that a refactoring changed no bit.

    python tools/fingerprint.py            # print one SHA-256 per case
    python tools/fingerprint.py --json F   # also write them to F

Each fingerprint hashes, as exact hexadecimal floats, every logged impact and maximum, the
metrics, the energy ledger and the final state of a 2 s run. The cases are the nominal damper,
the two designs of Fig. 10, a harmonic base (1 mm at 31.6 rad/s, first-order hold at 1 ms), and
the nominal damper under the circuit models 1 and 2 (chopped into 1 ms calls, so the snapshot-free
continuation path is covered too). The bits depend on the CPU (BLAS kernels): compare
fingerprints taken on one machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys

from piezo_fmu import Parameters, Simulator

T_END = 2.0
CASES = {
    "nominal": dict(),
    "designed": dict(x1=10e-3, m=0.2, d=10e-3),
    "poor": dict(x1=30e-3, m=0.02, d=3e-3),
    "harmonic": dict(p0=0.0, q0=0.0),
    "circuit": dict(voltage_model=1),
    "coupled": dict(voltage_model=2),
}


def _hex(value) -> str:
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_hex(v) for v in value) + "]"
    return repr(value)


def run(case: str) -> Simulator:
    sim_params = Parameters(**CASES[case])
    if case == "harmonic":
        Y, w, dt = 1e-3, 31.6, 1e-3
        n = int(math.ceil(T_END / dt - 1e-9))
        ts = [k * dt for k in range(n)] + [T_END]
        sim = Simulator(sim_params, y0=0.0, v0=Y * w)
        for ta, tb in zip(ts[:-1], ts[1:]):
            sim.advance(tb, Y * math.sin(w * ta), Y * w * math.cos(w * ta))
        return sim
    sim = Simulator(sim_params)
    if case in ("circuit", "coupled"):
        for k in range(1, 2001):
            sim.advance(k * 1e-3, 0.0, 0.0)
    else:
        sim.advance(T_END, 0.0, 0.0)
    return sim


def fingerprint(sim: Simulator) -> str:
    parts = [_hex(list(sim.state))]
    for impact in sim.impacts:
        parts.append(_hex([getattr(impact, name) for name in sorted(vars(impact))]))
    parts.append(_hex([list(m) for m in sim.maxima]))
    metrics = sim.metrics
    parts.append(_hex([getattr(metrics, name) for name in sorted(metrics.as_dict())]))
    parts.append(_hex(list(sim.energy)))
    parts.append(_hex([sim.voltage(-1), sim.voltage(+1), sim.base_force]))
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", help="write the fingerprints to this file too")
    args = parser.parse_args(argv)
    prints = {case: fingerprint(run(case)) for case in CASES}
    for case, digest in prints.items():
        print(f"{case:10s} {digest}")
    if args.json:
        with open(args.json, "w") as out:
            json.dump(prints, out, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
