"""The convergence table of docs/validation.md (Masri-Caughey): the harness's
symmetric two-impact orbit through the FMU against the closed form, as the contact stiffens.

    python tools/masri_caughey_table.py

prints the Markdown table (SI units; about a minute on one core).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from masri_caughey_fmu import table  # noqa: E402

from piezo_fmu_harness.fmu import FmuModel, Instance, discard  # noqa: E402


def main() -> None:
    model = FmuModel(ROOT / "fmus" / "PiezoImpactDamper.fmu")
    unzipdir = model.extract()
    try:
        rows = table(Instance(model, unzipdir))
    finally:
        discard(unzipdir)
    print("| case | K_eq factor | K_eq (N/m) | e | amplitude harness (mm) | closed form (mm) | rel. error "
          "| impact velocity harness (m/s) | closed form (m/s) | rel. error | max multiplier harness "
          "| closed form | stable (harness / closed form) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ea = r["amplitude"] / r["amplitude_closed"] - 1.0
        ev = r["impact_velocity"] / r["impact_velocity_closed"] - 1.0
        print(f"| {r['case']} | {r['factor']} | {r['K_eq']:.0e} | {r['e']:.6f} | {r['amplitude'] * 1e3:.5f} "
              f"| {r['amplitude_closed'] * 1e3:.5f} | {ea:+.2e} | {r['impact_velocity']:.5f} "
              f"| {r['impact_velocity_closed']:.5f} | {ev:+.2e} | {r['max_multiplier']:.4f} "
              f"| {r['max_multiplier_closed']:.4f} | {'yes' if r['stable'] else 'no'} / "
              f"{'yes' if r['stable_closed'] else 'no'} |")


if __name__ == "__main__":
    main()
