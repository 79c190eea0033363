"""Cost of the piezo FMU against a no-work FMU with the same variables (the floor).

Runs the nominal case (defaults, base at rest, 0 to 2 s) through fmpy at a 1e-4 s communication
step with both FMUs, in one process, and prints the times and their ratio (target: <= 2). The
floor FMU is built from ``benchmarks/null_slave.py`` into a scratch directory; the piezo FMU is
the committed ``fmus/PiezoImpactDamper.fmu`` (or ``--fmu``). The timing process never imports
``piezo_fmu`` itself, so each FMU runs the core bundled in it, as a host would.

Both FMUs have the project's loader as their binary. The floor is also timed with pythonfmu's
own binary in the loader's place (the same archive otherwise), and the ratio of the two is what
the loader costs (target: no measurable cost).

    python benchmarks/bench_fmu.py [--repeat N] [--fmu PATH]
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
PIEZO_FMU = HERE.parent / "fmus" / "PiezoImpactDamper.fmu"
STOP_TIME = 2.0
STEP = 1e-4
TARGET_RATIO = 2.0


def time_run(unzipdir: str, model_description) -> tuple[float, float]:
    """CPU and wall time (s) of one fmpy co-simulation of the nominal case, instantiation included.

    The ratio is taken on CPU time (this process only), which other work on a shared machine
    disturbs far less than wall time.
    """
    cpu, wall = time.process_time(), time.perf_counter()
    simulate_fmu(unzipdir, model_description=model_description, stop_time=STOP_TIME,
                 output_interval=STEP, validate=False)
    return time.process_time() - cpu, time.perf_counter() - wall


def write_floors(with_loader: Path, without_loader: Path) -> None:
    """The no-work FMU, and the same with pythonfmu's binary where the loader is (child process only)."""
    from piezo_fmu.fmi.loader import REAL_SUFFIX
    from piezo_fmu.fmi.archive import deterministic_zip
    from piezo_fmu.fmi.build import FMI2, build_bytes

    data = build_bytes(FMI2, HERE / "null_slave.py")
    with_loader.write_bytes(data)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        files = {name: archive.read(name) for name in archive.namelist()}
    for name in [name for name in files if name.endswith(REAL_SUFFIX)]:
        files[name[:-len(REAL_SUFFIX)] + ".so"] = files.pop(name)
    without_loader.write_bytes(deterministic_zip(files))


def build_floors(with_loader: Path, without_loader: Path) -> None:
    """Build the floor FMUs in a child process (which imports piezo_fmu; this one must not)."""
    code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); from pathlib import Path; import bench_fmu; "
            f"bench_fmu.write_floors(Path({str(with_loader)!r}), Path({str(without_loader)!r}))")
    subprocess.run([sys.executable, "-c", code], check=True)
    assert "piezo_fmu" not in sys.modules


def same_interface(a, b) -> bool:
    def table(md):
        return [(v.name, v.type, v.causality, v.variability, v.start) for v in md.modelVariables]
    return table(a) == table(b)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", type=Path, default=PIEZO_FMU)
    parser.add_argument("--repeat", type=int, default=5, help="runs of each FMU (the best counts)")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="bench_fmu_") as scratch:
        floor_fmu, bare_floor_fmu = Path(scratch) / "floor.fmu", Path(scratch) / "floor_without_loader.fmu"
        build_floors(floor_fmu, bare_floor_fmu)
        fmus = {"piezo": args.fmu, "floor": floor_fmu, "floor_without_loader": bare_floor_fmu}
        unzipped = {key: extract(str(path)) for key, path in fmus.items()}
        described = {key: read_model_description(str(path)) for key, path in fmus.items()}
        if not same_interface(described["piezo"], described["floor"]):
            raise SystemExit("the floor FMU does not have the piezo FMU's variables")

        times = {key: [] for key in fmus}
        for key in fmus:  # warm-up: first imports of numpy and the core
            time_run(unzipped[key], described[key])
        for _ in range(args.repeat):
            for key in fmus:  # interleaved, so that drift of the machine hits both alike
                times[key].append(time_run(unzipped[key], described[key]))

    steps = round(STOP_TIME / STEP)
    cpu = {key: min(c for c, _ in values) for key, values in times.items()}
    wall = {key: min(w for _, w in values) for key, values in times.items()}
    ratio = cpu["piezo"] / cpu["floor"]
    loader_ratio = cpu["floor"] / cpu["floor_without_loader"]
    print(json.dumps({
        "case": f"nominal, 0 to {STOP_TIME} s, communication step {STEP} s ({steps} steps), fmpy",
        "runs_each": args.repeat, "statistic": "best run",
        "piezo_cpu_s": cpu["piezo"], "floor_cpu_s": cpu["floor"],
        "piezo_wall_s": wall["piezo"], "floor_wall_s": wall["floor"],
        "piezo_us_per_step": 1e6 * cpu["piezo"] / steps,
        "floor_us_per_step": 1e6 * cpu["floor"] / steps,
        "wall_ratio": wall["piezo"] / wall["floor"],
        "ratio": ratio, "target_ratio": TARGET_RATIO, "within_target": ratio <= TARGET_RATIO,
        "floor_without_loader_cpu_s": cpu["floor_without_loader"],
        "floor_without_loader_us_per_step": 1e6 * cpu["floor_without_loader"] / steps,
        "loader_ratio": loader_ratio,
    }, indent=2))
    print(f"ratio piezo / floor = {ratio:.2f} (target <= {TARGET_RATIO:g}); "
          f"floor with / without the loader = {loader_ratio:.3f}")


if __name__ == "__main__":
    main()
