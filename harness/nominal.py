"""The nominal case of MODEL.md section 7: 2 s from p(0) = q(0) = 10 mm, base at rest."""

import json

from piezo_fmu import Parameters, Simulator

STOP_TIME = 2.0


def main() -> None:
    sim = Simulator(Parameters())
    sim.advance(STOP_TIME, 0.0, 0.0)
    m = sim.metrics
    summary = {
        "duration_s": STOP_TIME,
        "impact_count": m.impact_count,
        "DI_m_per_s": m.DI,
        "DI_cm_per_s": 100 * m.DI,
        "V_rms_V": m.V_rms,
        "P_ave_W": m.P_ave,
        "energy_balance_error_J": sim.energy.balance_error,
    }
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
