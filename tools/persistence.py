"""Does every motion a study called chaotic persist under a march twice as long?

    python tools/persistence.py FOLDER [FOLDER ...] [--factor 2] [--no-progress]

Each ``FOLDER`` is the results folder of a ``fractions``, ``basins`` or ``bifurcation`` run (told
apart by its files). Every start (fractions, basins) or point (bifurcation) whose motion the study
called chaotic or quasi-periodic is marched again from its start on the batch engine, under the
same drive, by the same rule (``piezo_fmu.solver.batch.attractors.settle``), with a budget ``--factor`` times
the study's. Its verdict **persists** when the longer march still finds it on no orbit; one that
reaches an orbit (or the motion without impacts) after the study's budget was a transient, and is
listed with the period it resolved at and what it reached.

Prints one JSON object: for each folder, the study, the budgets, the verdicts checked, how many
persisted, and each one that did not.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))  # the packages, when not installed

from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, damper, describe, settle  # noqa: E402

#: Verdicts that claim a motion persists.
CLAIMS = ("chaotic", "quasi-periodic")
#: The measuring window of the starts still open at the end (their measures are not used here).
WINDOW = 10


def _chunks(folder: Path) -> dict:
    from piezo_fmu_harness.store import PointStore

    return PointStore(folder).load()


def _header(folder: Path, name: str) -> dict:
    header = json.loads((folder / name).read_text())
    header.pop("fmu_guid", None)
    return header


def fractions_claims(folder: Path) -> tuple[dict, list]:
    """The fractions study's spec and its claims: (values, omega, Y, start, side, budget, where)."""
    from piezo_fmu_harness.studies.fractions.study import FractionSpec, outcome

    header = _header(folder, "fractions.json")
    spec = FractionSpec(**{**header, "ratios": tuple(header["ratios"]), "amplitudes": tuple(header["amplitudes"])})
    _, starts = outcome(spec, _chunks(folder))
    states, n = spec.states(), spec.starts
    claims = []
    for index, record in sorted(starts.items()):
        if record["motion"] in CLAIMS:
            f, j = divmod(index, n)
            claims.append({"omega": float(spec.omegas[f]), "amplitude": spec.amplitudes[f], "start": states[j],
                           "side": 0.0, "where": {"ratio": spec.ratios[f], "start": j},
                           "motion": record["motion"], "periods": record["periods"]})
    return {"study": "fractions", "values": spec.values, "samples": spec.samples, "tolerance": spec.tolerance,
            "budget": spec.max_cycles, "block": SettleSettings().block}, claims


def basins_claims(folder: Path) -> tuple[dict, list]:
    from piezo_fmu_harness.studies.basins.study import BasinSpec, outcome

    header = _header(folder, "basins.json")
    spec = BasinSpec(**{**header, "p0": tuple(header["p0"]), "dp0": tuple(header["dp0"])})
    _, starts = outcome(spec, _chunks(folder))
    grid = spec.starts()
    claims = [{"omega": spec.omega, "amplitude": spec.amplitude, "start": grid[i], "side": 0.0,
               "where": {"start": i, "p0": float(grid[i][0]), "dp0": float(grid[i][1])},
               "motion": record["motion"], "periods": record["periods"]}
              for i, record in sorted(starts.items()) if record["motion"] in CLAIMS]
    return {"study": "basins", "values": spec.values, "samples": spec.samples, "tolerance": spec.tolerance,
            "budget": spec.max_cycles, "block": SettleSettings().block}, claims


def bifurcation_claims(folder: Path) -> tuple[dict, list]:
    from piezo_fmu_harness.studies.bifurcation.study import BLOCK

    points = json.loads((folder / "points.json").read_text())
    from piezo_fmu_harness.datasets import open_dataset

    settings = json.loads(open_dataset(folder / "bifurcation.nc").attrs["settings"])
    claims = [{"omega": p["omega"], "amplitude": p["amplitude_Y"], "start": np.array(p["start"]),
               "side": p["start_side"], "where": {"direction": sweep["direction"], "ratio": p["ratio"]},
               "motion": p["motion"], "periods": p["periods"]}
              for sweep in points["sweeps"] for p in sweep["points"] if p["motion"] in CLAIMS]
    return {"study": "bifurcation", "values": points["values"], "samples": settings["samples"],
            "tolerance": settings["tolerance"], "budget": settings["max_cycles"], "block": BLOCK}, claims


def study_of(folder: Path):
    for name, reader in (("fractions.json", fractions_claims), ("basins.json", basins_claims),
                         ("points.json", bifurcation_claims)):
        if (folder / name).exists():
            return reader(folder)
    raise SystemExit(f"{folder}: not a results folder of fractions, basins or bifurcation")


def check(folder: Path, factor: float, progress: bool) -> dict:
    """March every claim of ``folder`` ``factor`` times the study's budget (see the module's text)."""
    from tqdm import tqdm

    begin = time.perf_counter()
    study, claims = study_of(folder)
    budget = int(round(factor * study["budget"]))
    report = {"folder": str(folder), "study": study["study"], "budget": study["budget"], "marched": budget,
              "claims": len(claims), "by_motion": {m: sum(c["motion"] == m for c in claims) for m in CLAIMS}}
    if claims:
        keys = sorted({(c["omega"], c["amplitude"]) for c in claims})
        drives = [HarmonicHold(omega, amplitude, 0.0, study["samples"]) for omega, amplitude in keys]
        groups = [keys.index((c["omega"], c["amplitude"])) for c in claims]
        settings = SettleSettings(tolerance=study["tolerance"], max_cycles=budget, block=study["block"],
                                  classify_cycles=WINDOW)
        with tqdm(total=len(claims), unit="start", desc=f"{study['study']} x{factor:g}", disable=not progress,
                  file=sys.stderr) as bar:
            def moved(done, total):
                bar.n = done
                bar.refresh()
            settled = settle(damper(study["values"]), drives, np.array([c["start"] for c in claims]), groups,
                             settings, sides=[c["side"] for c in claims], progress=moved)
        resolved = []
        for claim, label, periods in zip(claims, settled.labels.tolist(), settled.periods.tolist()):
            if label >= 0:
                reached = describe(settled.attractors[label])
                resolved.append({**claim["where"], "motion": claim["motion"], "resolved_at": int(periods),
                                 "reached": {k: reached[k] for k in ("kind", "order", "impacts_per_cycle")}})
        report.update(persisted=len(claims) - len(resolved) - int((settled.labels == -2).sum()),
                      set_aside=int((settled.labels == -2).sum()), resolved=resolved,
                      start_periods=int(settled.cycles))
    else:
        report.update(persisted=0, set_aside=0, resolved=[], start_periods=0)
    report["wall_s"] = time.perf_counter() - begin
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, metavar="FOLDER")
    parser.add_argument("--factor", type=float, default=2.0, help="the budget, times the study's (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if not args.factor >= 1.0:
        parser.error(f"--factor = {args.factor}: must be at least 1 (the study's own budget)")
    reports = [check(folder, args.factor, not args.no_progress) for folder in args.folders]
    print(json.dumps({"factor": args.factor, "folders": reports}, indent=2))
    return 0 if all(r["persisted"] == r["claims"] for r in reports) else 1


if __name__ == "__main__":
    sys.exit(main())
