"""Long run: harmonic base excitation for 1e5 impacts, in the core or through the FMU.

    .venv/bin/python benchmarks/long_run.py                      # the core, 100 000 impacts
    .venv/bin/python benchmarks/long_run.py --impacts 20000      # shorter
    .venv/bin/python benchmarks/long_run.py --fmu fmus/PiezoImpactDamper.fmu --impacts 20000

The case is a periodic regime: the nominal damper (``M = 1 kg``, ``K = 1000 N/m``) with
``C = 1 N s/m``, ``m = 0.1 kg``, ``d = 2 mm``, ``C_eq = 10 N s/m``, its base moved as
``y = Y sin(w t)`` with ``Y = 5 mm`` at ``w = sqrt(K/M)`` (resonance), fed as a first-order hold of
``N = 10`` samples per period (``y_k = Y sin(2 pi i/N)``, ``v_k = Y w cos(2 pi i/N)``, the phase taken
from the sample index ``i`` so that the input is exactly periodic). From rest it settles within a
few dozen periods on a period-1 orbit of 10 impacts per period: two chatter sequences of five
impacts, one on each barrier, the relative velocity falling from 0.17 to 0.005 m/s.

Printed: impacts, simulated and CPU time, the energy ledger's error (absolute, and relative to
the energy that flowed through: initial + |work of the base| + dissipated), memory (resident set
at 10 % of the run and at its end, its peak; with ``--tracemalloc`` the Python heap as well),
and the Poincare section (the state at the start of a period): its change over the last period
of the run, and its distance to that of a second run from another initial condition
(``p0 = 0.1 mm``, ``dq0 = 10 mm/s``), which shows both settle on the same orbit.

The core runs with ``log_limit=1000`` so its impact log is bounded; ``--fmu`` drives the FMU
through fmpy instead (``fmpy.fmi2.FMU2Slave``), whose memory is then what the FMU keeps.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time
import tracemalloc

#: The periodic case (SI): parameters different from the defaults, base amplitude, frequency.
CASE = {"m": 0.1, "C": 1.0, "d": 2e-3, "C_eq": 10.0}
AMPLITUDE = 5e-3
OMEGA = math.sqrt(1000.0 / 1.0)
CALLS_PER_PERIOD = 10
PERIOD = 2.0 * math.pi / OMEGA
#: The second initial condition of the Poincare comparison.
NEARBY = {"p0": 1e-4, "q0": 1e-4, "dq0": 0.01}
START = {"p0": 0.0, "q0": 0.0}


def base_sample(i: int) -> tuple[float, float]:
    """Base displacement (m) and velocity (m/s) held over call ``i`` of a period."""
    phase = 2.0 * math.pi * i / CALLS_PER_PERIOD
    return AMPLITUDE * math.sin(phase), AMPLITUDE * OMEGA * math.cos(phase)


def call_end(j: int, i: int) -> float:
    """End time (s) of call ``i`` of period ``j``."""
    return (j * CALLS_PER_PERIOD + i + 1) * PERIOD / CALLS_PER_PERIOD


class CoreDrive:
    """The core under the periodic drive."""

    def __init__(self, initial: dict, log_limit: int | None = 1000):
        from piezo_fmu import Parameters, Simulator

        self.sim = Simulator(Parameters(**CASE, **initial), log_limit=log_limit)

    def period(self, j: int) -> None:
        advance = self.sim.advance
        for i in range(CALLS_PER_PERIOD):
            advance(call_end(j, i), *base_sample(i))

    def section(self) -> tuple:
        s = self.sim.state
        return (s.p, s.dp, s.q, s.dq, s.side)

    def impacts(self) -> int:
        return self.sim.metrics.impact_count

    def ledger(self) -> tuple[float, float]:
        """(balance error J, energy flowed through J)."""
        e = self.sim.energy
        return e.balance_error, e.initial + abs(e.work_base) + e.dissipated


class FmuDrive:
    """The FMU, through fmpy, under the periodic drive."""

    def __init__(self, fmu: str, initial: dict):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        md = read_model_description(fmu)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="long_run")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        values = {**CASE, **initial}
        self.fmu.setReal([self.vr[k] for k in values], list(values.values()))
        self.fmu.setReal([self.vr["base_displacement"], self.vr["base_velocity"]], list(base_sample(0)))
        self.fmu.exitInitializationMode()
        self.t = 0.0
        self.initial_energy = 0.5 * 1000.0 * values["p0"] ** 2 + 0.5 * values["m"] * values.get("dq0", 0.0) ** 2

    def period(self, j: int) -> None:
        inputs = [self.vr["base_displacement"], self.vr["base_velocity"]]
        for i in range(CALLS_PER_PERIOD):
            end = call_end(j, i)
            self.fmu.setReal(inputs, list(base_sample(i)))
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=end - self.t)
            self.t = end

    def _get(self, *names):
        return self.fmu.getReal([self.vr[n] for n in names])

    def section(self) -> tuple:
        return tuple(self._get("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity"))

    def impacts(self) -> int:
        return self.fmu.getInteger([self.vr["impact_count"]])[0]

    def ledger(self) -> tuple[float, float]:
        error, dissipated = self._get("energy_balance_error", "energy_dissipated")
        # The work of the base is not an output: at most dissipated + the energy now (a few mJ).
        return error, self.initial_energy + 2.0 * dissipated


def rss_bytes() -> int:
    """Resident set size of this process now (bytes)."""
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def distance(a: tuple, b: tuple) -> float:
    """Largest difference of the Poincare sections (positions in m, velocities in m/s)."""
    return max(abs(x - y) for x, y in zip(a, b))


def run(drive, impacts: int, trace: bool = False, report=print) -> dict:
    """Drive whole periods until ``impacts`` impacts; measure as we go."""
    begin_cpu = time.process_time()
    if trace:
        tracemalloc.start()
    j, early = 0, None
    previous = drive.section()
    while drive.impacts() < impacts:
        previous = drive.section()
        drive.period(j)
        j += 1
        if early is None and drive.impacts() >= impacts // 10:
            early = (drive.impacts(), rss_bytes(), tracemalloc.get_traced_memory()[0] if trace else 0)
    late = (drive.impacts(), rss_bytes(), tracemalloc.get_traced_memory()[0] if trace else 0)
    heap_peak = tracemalloc.get_traced_memory()[1] if trace else 0
    if trace:
        tracemalloc.stop()
    error, flowed = drive.ledger()
    early = early or late
    grown = max(1, late[0] - early[0])
    return {
        "periods": j, "impacts": late[0], "simulated_s": j * PERIOD, "cpu_s": time.process_time() - begin_cpu,
        "ledger_error_J": error, "energy_flowed_J": flowed, "ledger_relative": abs(error) / flowed,
        "rss_early_MB": early[1] / 2**20, "rss_end_MB": late[1] / 2**20, "rss_peak_MB": peak_rss_bytes() / 2**20,
        "rss_growth_per_impact_B": (late[1] - early[1]) / grown,
        "heap_growth_per_impact_B": (late[2] - early[2]) / grown if trace else math.nan,
        "heap_peak_MB": heap_peak / 2**20 if trace else math.nan,
        "section": drive.section(), "section_change_last_period": distance(drive.section(), previous),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--impacts", type=int, default=100_000, help="impacts to run (default 100000)")
    parser.add_argument("--fmu", default=None, help="drive this FMU through fmpy instead of the core")
    parser.add_argument("--tracemalloc", action="store_true", help="also trace the Python heap (slower)")
    parser.add_argument("--compare-periods", type=int, default=400,
                        help="periods of the second run from a nearby initial condition (default 400)")
    args = parser.parse_args(argv)

    make = (lambda initial: FmuDrive(args.fmu, initial)) if args.fmu else (lambda initial: CoreDrive(initial))
    what = f"FMU {args.fmu} through fmpy" if args.fmu else "core, log_limit=1000"
    print(f"long run ({what}): Y = {AMPLITUDE * 1e3:g} mm at w = {OMEGA:.4g} rad/s, {CALLS_PER_PERIOD} calls "
          f"per period, parameters {CASE}")
    result = run(make(START), args.impacts, trace=args.tracemalloc)
    print(f"  impacts {result['impacts']} in {result['periods']} periods = {result['simulated_s']:.1f} s simulated, "
          f"{result['cpu_s']:.1f} s CPU ({result['impacts'] / result['cpu_s']:.0f} impacts per CPU second)")
    print(f"  ledger error {result['ledger_error_J']:.3e} J of {result['energy_flowed_J']:.4g} J flowed "
          f"= {result['ledger_relative']:.2e} relative (limit 1e-8)")
    print(f"  memory: RSS {result['rss_early_MB']:.1f} MB at 10 % of the run, {result['rss_end_MB']:.1f} MB at the end "
          f"({result['rss_growth_per_impact_B']:.1f} B per impact), peak {result['rss_peak_MB']:.1f} MB")
    if args.tracemalloc:
        print(f"  Python heap: {result['heap_growth_per_impact_B']:.1f} B per impact after 10 % of the run, "
              f"peak {result['heap_peak_MB']:.1f} MB")
    print(f"  Poincare section (p, p', q, q') at the last period start: "
          f"{', '.join(f'{x:.12g}' for x in result['section'][:4])}; change over the last period "
          f"{result['section_change_last_period']:.2e}")
    other = make(NEARBY)
    for j in range(args.compare_periods):
        other.period(j)
    gap = distance(other.section(), result["section"])
    print(f"  from {NEARBY} after {args.compare_periods} periods: section differs by {gap:.2e} "
          f"({'same periodic orbit' if gap < 1e-9 else 'NOT the same orbit'})")
    ok = result["ledger_relative"] < 1e-8 and gap < 1e-9
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
