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

All these FMUs have the project's loader as their linux binary. Each floor is also timed with
pythonfmu's own binary in the loader's place (the same archive otherwise): the ratio of the two
is what the loader costs a step (target: no measurable cost).

    python benchmarks/bench_fmu.py [--repeat N] [--fmi 2 --fmi 3]
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from fmpy import extract, read_model_description, simulate_fmu

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
    from piezo_fmu.build.loader import REAL_SUFFIX

    data = build_bytes(TARGETS[version], FLOOR_SLAVES[version], (HERE / "no_core.py",))
    with_loader.write_bytes(data)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        files = {name: archive.read(name) for name in archive.namelist()}
    for name in [name for name in files if name.endswith(REAL_SUFFIX)]:
        files[name[:-len(REAL_SUFFIX)] + ".so"] = files.pop(name)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs of each FMU (the best counts)")
    parser.add_argument("--fmi", type=int, choices=(2, 3), action="append", help="FMI version (default: both)")
    args = parser.parse_args()
    results = []
    versions = args.fmi or (2, 3)
    with tempfile.TemporaryDirectory(prefix="bench_fmu_") as scratch:
        floors = {version: (Path(scratch) / f"floor{version}.fmu", Path(scratch) / f"floor{version}_without_loader.fmu")
                  for version in versions}
        for version, (floor, bare_floor) in floors.items():  # before any FMU has run in this process
            build_floors(version, floor, bare_floor)
        for version in versions:
            results.append(measure(version, args.repeat, *floors[version]))
    print(json.dumps(results, indent=2))
    for r in results:
        print(f"FMI {r['fmi_version']}: piezo {r['piezo_us_per_step']:.1f} us/step, floor {r['floor_us_per_step']:.1f} "
              f"us/step, ratio {r['ratio']:.2f} (target <= {TARGET_RATIO:g}); floor with / without the loader "
              f"{r['loader_ratio']:.3f}")


if __name__ == "__main__":
    main()
