"""The FMI 3.0 FMU as Model Exchange in fmpy's CVode at each tolerance, beside the exact core.

Run: ``.venv/bin/python benchmarks/bench_me.py [--repeats N]``. See ``benchmarks/README.md``.

The nominal case (docs/model.md section 7, 2 s, base at rest), timed side by side in one process:
- the core itself (``Simulator(Parameters()).advance(2.0, 0.0, 0.0)``), best of 20;
- the FMI 3.0 FMU as co-simulation (the exact core inside) through ``fmpy.simulate_fmu`` with
  ``output_interval=1e-3``;
- the same FMU as Model Exchange through ``fmpy.simulate_fmu`` with CVode at rtol 1e-6 to 1e-12,
  ``output_interval=1e-3`` and the events recorded;
each FMU run best of ``--repeats`` (wall and CPU time). Then the accuracy of each Model Exchange
run against the core (the convergence table in docs/fmu.md).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from fmpy import simulate_fmu  # noqa: E402
from me_host import FMU3, STOP_TIME, errors, me_run  # noqa: E402

from piezo_fmu import Parameters, Simulator  # noqa: E402

RTOLS = (1e-6, 1e-8, 1e-10, 1e-12)


def best_of(fn, repeats: int):
    """(best wall time, best CPU time, last result) over ``repeats`` calls."""
    best, best_cpu, out = math.inf, math.inf, None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best, best_cpu = min(best, time.perf_counter() - t0), min(best_cpu, time.process_time() - c0)
    return best, best_cpu, out


def run_core() -> Simulator:
    sim = Simulator(Parameters(), log_limit=None)
    sim.advance(STOP_TIME, 0.0, 0.0)
    return sim


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs of each FMU case (best is kept)")
    args = parser.parse_args(argv)
    print(f"load average before: {os.getloadavg()} (other programs on the cores slow the wall times)")
    core_wall, core_cpu, core = best_of(run_core, 20)
    cs_wall, cs_cpu, _ = best_of(lambda: simulate_fmu(str(FMU3), fmi_type="CoSimulation", stop_time=STOP_TIME,
                                                      output_interval=1e-3), args.repeats)
    runs, costs = {}, {}
    for rtol in RTOLS:
        wall, cpu, runs[rtol] = best_of(lambda: me_run(rtol), args.repeats)
        costs[rtol] = (wall, cpu)
    print(f"nominal case, {STOP_TIME:g} s; wall and CPU time, best of {args.repeats} (the core: of 20); "
          "the ratios are of CPU times, the steadier under load")
    print(f"{'run':<32s} {'wall (s)':>9s} {'CPU (s)':>9s} {'x core':>8s} {'x CS FMU':>9s}")
    rows = [("core (Simulator)", core_wall, core_cpu), ("FMI 3.0 CS FMU, fmpy, 1 ms", cs_wall, cs_cpu)]
    rows += [(f"FMI 3.0 ME FMU, CVode rtol {rtol:g}", wall, cpu) for rtol, (wall, cpu) in costs.items()]
    for name, wall, cpu in rows:
        print(f"{name:<32s} {wall:9.4f} {cpu:9.4f} {cpu / core_cpu:8.1f} {cpu / cs_cpu:9.2f}")
    table = errors(runs, core)
    final = core.readings()
    print(f"\naccuracy against the core ({final['impact_count']} impacts; V_rms {final['voltage_rms']:.6g} V, "
          f"DI {final['damping_inclination']:.6g} m/s)")
    print(f"{'rtol':>7s} {'impacts':>7s} {'1st impact (s)':>15s} {'first 10 (s)':>13s} {'all (s)':>9s} "
          f"{'V_rms':>9s} {'DI':>9s} {'ledger':>9s}")
    for rtol, row in table.items():
        print(f"{rtol:7.0e} {row['count']:7d} {row['first']:15.1e} {row['ten']:13.1e} {row['all']:9.1e} "
              f"{row['V_rms']:9.1e} {row['DI']:9.1e} {row['ledger']:9.1e}")
    print("(impact-time errors are absolute; V_rms and DI relative; ledger: max |energy_balance_error| over "
          "the run / initial energy)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
