"""Cost of a co-simulation step of the piezo FMUs against no-work FMUs with the same variables.

Runs the nominal case (defaults, base at rest, 0 to 2 s) through fmpy's ``simulate_fmu`` at a
1e-4 s communication step (every output read at every step), in one process, for each FMI
version: the piezo FMU and its floor, interleaved, best of ``--repeat`` runs; it prints the times
and their ratio (target: <= 1.5).

The floors are the piezo slaves themselves with the core taken out (``null_slave.py`` for FMI 2.0,
``null_slave3.py`` for FMI 3.0, both over ``no_core.py``): the same variables, type checks and
value-reference tables, the outputs read exactly as the piezo FMUs read theirs, but ``do_step``
does no work. So the ratio is what the core and its readings add on top of FMI, the builder's
binary and fmpy. The piezo FMUs are the committed ``fmus/*.fmu``. The timing process never imports
``piezo_fmu``: each FMU runs the core bundled in it, as a host would.

All these FMUs have the project's loader as their linux and Windows binaries. Each floor is also
timed with pythonfmu's own binary in the loader's place (the same archive otherwise): the ratio
of the two is what the loader costs a step (target: no measurable cost). The Windows row does
the same under Wine, in fmpy inside the tests' embeddable CPython 3.13.2 (``tests/windows.py``):
only that ratio is reported, as Wine's absolute times say nothing of Windows'.

The last row steps the FMI 2.0 FMU as the harness marches it (``tests/fmpy_march.py``): the
first-order hold of a harmonic base at 1.25 ``w_n`` (1 mm, 64 steps a period, a new bracket of the
core every step, impacts every period, the circuits harvesting), reading after every step either
every output or the state alone (the displacements and velocities): the energy ledger's
quadratures are made only when one of its outputs is read. Both interleaved, best of ``--repeat``.

    python benchmarks/bench_fmu.py [--repeat N] [--fmi 2 --fmi 3] [--no-windows]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

HERE = Path(__file__).resolve().parent
FMUS = {2: HERE.parent / "fmus" / "PiezoImpactDamper.fmu", 3: HERE.parent / "fmus" / "PiezoImpactDamper3.fmu"}
FLOOR_SLAVES = {2: HERE / "null_slave.py", 3: HERE / "null_slave3.py"}
STOP_TIME = 2.0
STEP = 1e-4
TARGET_RATIO = 1.5


def time_run(unzipdir: str, model_description) -> tuple[float, float]:
    """CPU and wall time (s) of one fmpy co-simulation of the nominal case, instantiation included.

    The ratio is taken on CPU time (this process only), which other work on a shared machine
    disturbs far less than wall time.
    """
    cpu, wall = time.process_time(), time.perf_counter()
    simulate_fmu(unzipdir, model_description=model_description, stop_time=STOP_TIME,
                 output_interval=STEP, validate=False, fmi_type="CoSimulation")
    return time.process_time() - cpu, time.perf_counter() - wall


def write_floors(version: int, with_loader: Path, without_loader: Path) -> None:
    """The no-work FMU, and the same with pythonfmu's binary where the loader is (child process only)."""
    from piezo_fmu.build.archive import deterministic_zip
    from piezo_fmu.build.fmus import TARGETS, build_bytes
    from piezo_fmu.build.loader import LIBRARY_SUFFIX, REAL_SUFFIXES

    data = build_bytes(TARGETS[version], FLOOR_SLAVES[version], (HERE / "no_core.py",))
    with_loader.write_bytes(data)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        files = {name: archive.read(name) for name in archive.namelist()}
    for platform, real_suffix in REAL_SUFFIXES.items():
        for name in [name for name in files if name.endswith(real_suffix)]:
            files[name[:-len(real_suffix)] + LIBRARY_SUFFIX[platform]] = files.pop(name)
    without_loader.write_bytes(deterministic_zip(files))


def build_floors(version: int, with_loader: Path, without_loader: Path) -> None:
    """Build the no-work FMUs in a child process (which imports piezo_fmu; this one must not)."""
    code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); from pathlib import Path; import bench_fmu; "
            f"bench_fmu.write_floors({version}, Path({str(with_loader)!r}), Path({str(without_loader)!r}))")
    subprocess.run([sys.executable, "-c", code], check=True)
    assert "piezo_fmu" not in sys.modules


def same_interface(a, b) -> bool:
    def table(md):
        return [(v.name, v.type, v.causality, v.variability, v.start) for v in md.modelVariables]
    return table(a) == table(b)


def measure(version: int, repeat: int, floor_fmu: Path, bare_floor_fmu: Path) -> dict:
    fmus = {"piezo": FMUS[version], "floor": floor_fmu, "floor_without_loader": bare_floor_fmu}
    unzipped = {key: extract(str(path)) for key, path in fmus.items()}
    described = {key: read_model_description(str(path)) for key, path in fmus.items()}
    if not same_interface(described["piezo"], described["floor"]):
        raise SystemExit(f"the FMI {version} floor FMU does not have the piezo FMU's variables")
    times = {key: [] for key in fmus}
    for key in fmus:  # warm-up: first imports of numpy and the core
        time_run(unzipped[key], described[key])
    for _ in range(repeat):
        for key in fmus:  # interleaved, so that drift of the machine hits both alike
            times[key].append(time_run(unzipped[key], described[key]))
    steps = round(STOP_TIME / STEP)
    cpu = {key: min(c for c, _ in values) for key, values in times.items()}
    wall = {key: min(w for _, w in values) for key, values in times.items()}
    ratio = cpu["piezo"] / cpu["floor"]
    return {
        "fmi_version": version,
        "case": f"nominal, 0 to {STOP_TIME} s, communication step {STEP} s ({steps} steps), fmpy simulate_fmu",
        "runs_each": repeat, "statistic": "best run",
        "piezo_us_per_step": 1e6 * cpu["piezo"] / steps, "floor_us_per_step": 1e6 * cpu["floor"] / steps,
        "core_us_per_step": 1e6 * (cpu["piezo"] - cpu["floor"]) / steps,
        "wall_ratio": wall["piezo"] / wall["floor"],
        "ratio": ratio, "target_ratio": TARGET_RATIO, "within_target": ratio <= TARGET_RATIO,
        "floor_without_loader_us_per_step": 1e6 * cpu["floor_without_loader"] / steps,
        "loader_ratio": cpu["floor"] / cpu["floor_without_loader"],
    }


#: Run by the Windows CPython under Wine: the best CPU time of each floor, as JSON.
WINDOWS_TIMING = """
import json, sys
sys.modules["_wmi"] = None  # Python 3.13's platform module asks WMI through propsys, which Wine 8 lacks
here, repeat, fmus = sys.argv[1], int(sys.argv[2]), dict(zip(("floor", "floor_without_loader"), sys.argv[3:5]))
sys.path.insert(0, here)
import bench_fmu
unzipped = {key: bench_fmu.extract(path) for key, path in fmus.items()}
described = {key: bench_fmu.read_model_description(path) for key, path in fmus.items()}
times = {key: [] for key in fmus}
for key in fmus:
    bench_fmu.time_run(unzipped[key], described[key])
for _ in range(repeat):
    for key in fmus:
        times[key].append(bench_fmu.time_run(unzipped[key], described[key])[0])
print(json.dumps({key: min(values) for key, values in times.items()}))
"""


def measure_windows(version: int, repeat: int, floor_fmu: Path, bare_floor_fmu: Path) -> dict:
    """The loader's cost on Windows, under Wine: the floor with the loader against the floor with
    pythonfmu's DLL in its place, in fmpy inside the embeddable CPython of the tests."""
    sys.path.insert(0, str(HERE.parent))
    from tests import windows

    windows.wine_prefix()
    python = windows.embeddable_python((windows.NUMPY, *windows.FMPY))
    completed = windows.run([str(windows.WINE), str(python / "python.exe"), "-c", WINDOWS_TIMING,
                             windows.windows_path(HERE), str(repeat), windows.windows_path(floor_fmu),
                             windows.windows_path(bare_floor_fmu)], timeout=1800)
    if completed.returncode != 0:
        raise SystemExit(f"the Windows timing failed under Wine:\n{completed.stderr[-3000:]}")
    cpu = json.loads(completed.stdout.strip().splitlines()[-1])
    return {"fmi_version": version, "platform": f"Windows under Wine, CPython {windows.CPYTHON_VERSION} embeddable",
            "case": f"the floor FMU, 0 to {STOP_TIME} s, communication step {STEP} s, fmpy simulate_fmu",
            "runs_each": repeat, "statistic": "best run",
            "loader_ratio": cpu["floor"] / cpu["floor_without_loader"]}


HOLD_PERIODS = 20
STATE_OUTPUTS = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity")


def time_hold(slave: FMU2Slave, variables: dict, refs: list) -> float:
    """CPU time (s) of :data:`HOLD_PERIODS` periods of the harmonic hold from the nominal start,
    reading the Real outputs ``refs`` after every step."""
    n, omega, amplitude = 64, 1.25 * math.sqrt(1000.0), 1e-3
    h = 2.0 * math.pi / omega / n
    scaled = amplitude / (math.sin(math.pi / n) / (math.pi / n)) ** 2  # the fundamental is Y sin(w t), as the harness's
    nodes = [scaled * math.sin(2.0 * math.pi * k / n) for k in range(n + 1)]
    inputs = [variables["base_displacement"].valueReference, variables["base_velocity"].valueReference]
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setInteger([variables["voltage_model"].valueReference], [1])
    slave.setReal([variables["R_load"].valueReference], [3.6e6])
    slave.exitInitializationMode()
    cpu = time.process_time()
    step = 0
    for _ in range(HOLD_PERIODS):
        for k in range(n):
            slave.setReal(inputs, [nodes[k], (nodes[k + 1] - nodes[k]) / h])
            slave.doStep(currentCommunicationPoint=step * h, communicationStepSize=(step + 1) * h - step * h)
            step += 1
            slave.getReal(refs)
    return time.process_time() - cpu


def measure_hold(repeat: int) -> dict:
    """Steps under the harness's hold, every output read against the state alone (FMI 2.0)."""
    path = FMUS[2]
    described = read_model_description(str(path))
    variables = {v.name: v for v in described.modelVariables}
    reads = {"every_output": [v.valueReference for v in described.modelVariables
                              if v.causality == "output" and v.type == "Real"],
             "state_only": [variables[name].valueReference for name in STATE_OUTPUTS]}
    slave = FMU2Slave(guid=described.guid, unzipDirectory=extract(str(path)), instanceName="hold",
                      modelIdentifier=described.coSimulation.modelIdentifier)
    slave.instantiate()
    times = {key: [] for key in reads}
    for key, refs in reads.items():  # warm-up
        time_hold(slave, variables, refs)
    for _ in range(repeat):
        for key, refs in reads.items():
            times[key].append(time_hold(slave, variables, refs))
    slave.terminate()
    slave.freeInstance()
    steps = HOLD_PERIODS * 64
    best = {key: min(values) for key, values in times.items()}
    return {"fmi_version": 2, "case": f"the harness's hold at 1.25 w_n, 1 mm, {steps} steps of T/64, voltage_model 1, "
                                      "fmpy FMU2Slave", "runs_each": repeat, "statistic": "best run",
            "every_output_us_per_step": 1e6 * best["every_output"] / steps,
            "state_only_us_per_step": 1e6 * best["state_only"] / steps,
            "state_only_over_every_output": best["state_only"] / best["every_output"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs of each FMU (the best counts)")
    parser.add_argument("--fmi", type=int, choices=(2, 3), action="append", help="FMI version (default: both)")
    parser.add_argument("--no-windows", action="store_true", help="leave out the Windows row (Wine)")
    args = parser.parse_args()
    results, windows_results = [], []
    versions = args.fmi or (2, 3)
    with tempfile.TemporaryDirectory(prefix="bench_fmu_") as scratch:
        floors = {version: (Path(scratch) / f"floor{version}.fmu", Path(scratch) / f"floor{version}_without_loader.fmu")
                  for version in versions}
        for version, (floor, bare_floor) in floors.items():  # before any FMU has run in this process
            build_floors(version, floor, bare_floor)
        for version in versions:
            results.append(measure(version, args.repeat, *floors[version]))
        for version in () if args.no_windows else versions:
            windows_results.append(measure_windows(version, args.repeat, *floors[version]))
    hold = measure_hold(args.repeat)
    print(json.dumps(results + windows_results + [hold], indent=2))
    for r in results:
        print(f"FMI {r['fmi_version']}: piezo {r['piezo_us_per_step']:.1f} us/step, floor {r['floor_us_per_step']:.1f} "
              f"us/step, ratio {r['ratio']:.2f} (target <= {TARGET_RATIO:g}); floor with / without the loader "
              f"{r['loader_ratio']:.3f}")
    for r in windows_results:
        print(f"FMI {r['fmi_version']}, Windows under Wine: floor with / without the loader {r['loader_ratio']:.3f}")
    print(f"FMI 2, the harness's hold: every output read {hold['every_output_us_per_step']:.1f} us/step, "
          f"the state alone {hold['state_only_us_per_step']:.1f} us/step, "
          f"ratio {hold['state_only_over_every_output']:.2f}")


if __name__ == "__main__":
    main()
