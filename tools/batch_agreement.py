"""The batch engine against the scalar core and the FMU on stable orbits: the table of
``docs/validation.md`` ("The batch engine").

    python tools/batch_agreement.py

For each case (the damper, the frequency ratio, ``Y`` = 1 mm): a point of its two-impact orbit (Newton
on the batch engine from a marched state), then 100 periods from it by the batch engine, by the
scalar core (``Simulator``, the same hold) and by the FMI 2.0 FMU (the harness's drive): the largest
difference of the section states (m) and whether the contact onsets agree in every period.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from piezo_fmu import Parameters, Simulator  # noqa: E402
from piezo_fmu.solver.batch import Ensemble, HarmonicHold  # noqa: E402
from piezo_fmu.solver.batch.attractors.orbits import OrbitFinder  # noqa: E402
from piezo_fmu.solver.batch.model import BatchModel  # noqa: E402
from piezo_fmu_harness.fmu import FmuModel, Instance, default_fmu_path  # noqa: E402
from piezo_fmu_harness.periodic.drive import HarmonicDrive  # noqa: E402

W_N = math.sqrt(1000.0)
PERIODS = 100
CASES = (("nominal, circuit one-way (3.59 MOhm)", Parameters(voltage_model=1, R_load=3.59e6), 1.2),
         ("coupled circuit (3.59 MOhm)", Parameters(voltage_model=2, R_load=3.59e6), 1.2),
         ("coupled circuit (52 kOhm)", Parameters(voltage_model=2, R_load=52e3), 1.2),
         ("stiff contact (the printed K_eq = 46.8 MN/m)", Parameters(barrier_mode=1, voltage_model=0), 1.2),
         ("nominal, below resonance", Parameters(voltage_model=1, R_load=3.59e6), 0.8))


def main() -> int:
    model = FmuModel(default_fmu_path())
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    print("| case | w / w_n | onsets in 100 periods | batch - core (m) | batch - FMU (m) | onsets equal |")
    print("|---|---|---|---|---|---|")
    for name, params, ratio in CASES:
        drive = HarmonicHold(ratio * W_N, 1e-3)
        finder = OrbitFinder(BatchModel.of(params), [drive], 1e-9 * drive.amplitude)
        marched = finder.march([[2e-3, 0.0, 2e-3, 0.0]], [0.0], [0], 300)["sections"][-1]
        x = finder.newton(marched, np.zeros(1), np.zeros(1, int), 1)[0][0]
        batch = Ensemble(params, drive, [x]).advance(PERIODS)
        y, v = drive.nodes()
        sim = Simulator(params.replace(p0=x[0], dp0=x[1], q0=x[2], dq0=x[3]), y0=y[0], v0=v[0])
        core, onsets, count = [], [], 0
        for period in range(PERIODS):
            for k in range(drive.samples):
                i = period * drive.samples + k
                sim.advance((i + 1) * drive.step, y[k], v[k])
            s = sim.state
            core.append((s.p, s.dp, s.q, s.dq))
            onsets.append(sim.metrics.impact_count - count)
            count = sim.metrics.impact_count
        values = {k: val for k, val in params.as_dict().items() if k not in ("p0", "q0", "dp0", "dq0")}
        fmu = HarmonicDrive(instance, values, drive.omega, drive.amplitude, drive.samples)
        fmu.start(x, 0.0)
        fmu_sections = np.array(fmu.advance(PERIODS))
        equal = batch["impacts"][:, 0].tolist() == onsets and fmu.totals()[0] == sum(onsets)
        print(f"| {name} | {ratio:g} | {sum(onsets)} | {np.abs(batch['sections'][:, 0] - core).max():.1e} | "
              f"{np.abs(batch['sections'][:, 0] - fmu_sections).max():.1e} | {'yes' if equal else 'no'} |")
    instance.free()
    return 0


if __name__ == "__main__":
    sys.exit(main())
