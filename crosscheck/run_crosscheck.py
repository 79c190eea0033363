"""Re-run an importer against the cross-check reference and report pass or fail.

Usage (from the repository root, with the project's Python)::

    python crosscheck/run_crosscheck.py IMPORTER [IMPORTER ...] [--fmu PATH] [--out DIR]
    python crosscheck/run_crosscheck.py --write      # rewrite _in.csv, _ref.opt and _ref.csv

IMPORTER is one of ``fmpy``, ``libcosim``, ``ecos``, ``native`` (the project's C host),
``fmpy-simulate`` (fmpy's own ``simulate_fmu``; see ReadMe.md for why it is not bit-identical
to the others), or ``fmpy-fmi3``, ``ecos-fmi3`` and ``native-fmi3`` (the FMI 3.0 FMU in fmpy, ecos
and the C host). ``all``
runs all but ``fmpy-simulate``. For each importer the script prints the worst relative
deviation of every output from ``PiezoImpactDamper_ref.csv`` (the band is defined in ReadMe.md
and in :mod:`crosscheck.scenario`), whether the result is bit-identical to the reference, and
``PASS`` or ``FAIL``; with ``--out`` it writes ``<importer>_out.csv`` there. The exit status is
0 when every importer passes and 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from crosscheck import importers, scenario  # noqa: E402

DEFAULT_SET = ("fmpy", "libcosim", "ecos", "native", "fmpy-fmi3", "ecos-fmi3", "native-fmi3")


def write_files(fmu: Path) -> None:
    """Rewrite the input table, the options and the reference (with the fmpy driver)."""
    scenario.write_inputs()
    scenario.write_opt()
    result = importers.run_fmpy(fmu)
    scenario.write_csv(scenario.REF_CSV, result.time, result.outputs)
    size = scenario.REF_CSV.stat().st_size
    print(f"wrote {scenario.IN_CSV.name}, {scenario.REF_OPT.name}, {scenario.REF_CSV.name} ({size} bytes)")


def check(importer: str, fmu: Path | None, out: Path | None = None) -> bool:
    options = scenario.read_opt()
    ref_time, ref = scenario.read_reference()
    if (ref_time[0], ref_time[-1]) != (options["StartTime"], options["StopTime"]):
        raise SystemExit(f"{scenario.REF_CSV.name} does not span StartTime..StopTime of {scenario.REF_OPT.name}")
    started = time.perf_counter()
    result = importers.run(importer, fmu)
    elapsed = time.perf_counter() - started
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        scenario.write_csv(out / f"{importer}_out.csv", result.time, result.outputs)
    comparison = scenario.compare(result.time, result.outputs, ref_time, ref, rel_tol=options["RelTol"])
    print(f"== {importer} ({elapsed:.1f} s, {len(result.time)} points, RelTol {options['RelTol']:g})")
    print(comparison.report())
    for problem in comparison.problems[:20]:
        print(f"  problem: {problem}")
    identical = "bit-identical to the reference" if comparison.all_bit_identical else "not bit-identical"
    verdict = "PASS" if comparison.passed else "FAIL"
    print(f"{importer}: {verdict} (max relative deviation {comparison.max_relative:.3e}; {identical})")
    return comparison.passed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("importers", nargs="*", help=f"importers: {', '.join(importers.IMPORTERS)} or all")
    parser.add_argument("--fmu", type=Path, default=None,
                        help=f"the FMU (default: {scenario.FMU_PATH.name}, {scenario.FMU3_PATH.name} for the -fmi3 importers)")
    parser.add_argument("--out", type=Path, default=None, help="write <importer>_out.csv into this folder")
    parser.add_argument("--write", action="store_true", help="rewrite the input, options and reference files")
    args = parser.parse_args(argv)
    if args.write:
        write_files(args.fmu or scenario.FMU_PATH)
        return 0
    chosen = []
    for name in args.importers or ["all"]:
        chosen.extend(DEFAULT_SET if name == "all" else [name])
    for name in chosen:
        if name not in importers.IMPORTERS:
            parser.error(f"unknown importer {name!r}")
    results = {name: check(name, args.fmu, args.out) for name in chosen}
    if len(results) > 1:
        print("summary: " + ", ".join(f"{n} {'PASS' if ok else 'FAIL'}" for n, ok in results.items()))
    return 0 if all(results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
