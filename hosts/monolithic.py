"""The host model of ``hosts/coupled.py`` integrated by one solver: the damper's FMI 3.0 Model
Exchange FMU and the floor's equation share scipy's ``solve_ivp``.

    python hosts/monolithic.py [--stop 5] [--rtol 1e-10] [--no-cosim]

The floor is the SDOF structure of ``hosts/primary_structure.py`` under the same synthetic record
(``hosts/primary_structure_ground.py``), written here as an ODE; the damper is
``fmus/PiezoImpactDamper3.fmu`` through fmpy's FMI 3.0 Model Exchange API. One state vector holds
the floor's ``X, X'`` and its ledger's work of the ground and dissipation, and the damper's
continuous states. At every evaluation the floor's absolute displacement and velocity are the
damper's inputs ``base_displacement`` and ``base_velocity`` and its output ``base_force`` acts on
the floor:

    M_s X'' = -K_s (X - u_g) - C_s (X' - v_g) + base_force.

The damper's event indicators are terminal events of ``solve_ivp``; at each, the state is taken
just past the crossing, handed to the FMU (event mode, ``updateDiscreteStates`` until it needs no
more, continuous-time mode) and the integration restarts from the state the FMU returns.

Nothing is held between the two: the ledger ``R = (E_s + E_d) - (E_s + E_d)(0) - W_ground + D_s + D_d``
(the notation of ``hosts/coupled.py``) closes to the solver's tolerance. The script then runs the
co-simulation of ``hosts/coupled.py`` (OSP libcosim, fixed step) at shrinking steps and prints how
far it is from this result, and its ledger residual, which is the coupling error.
"""

from __future__ import annotations

import argparse
import ctypes
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Model
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(REPO), str(HERE)]

from hosts import coupled  # noqa: E402
from primary_structure import PARAMETERS  # noqa: E402
from primary_structure_ground import GroundMotion  # noqa: E402

DAMPER_FMU3 = REPO / "fmus" / "PiezoImpactDamper3.fmu"
FLOOR = {name: start for name, start, _ in PARAMETERS}
#: The damper's outputs recorded, and the co-simulation steps compared (s).
OUTPUTS = ("main_displacement", "main_velocity", "impactor_velocity", "deflection_left", "deflection_right",
           "base_force", "energy_dissipated", "energy_balance_error")
STEPS = (4e-3, 2e-3, 1e-3, 5e-4)


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class DamperME:
    """The damper's FMU as Model Exchange, initialized (through its initial event update)."""

    def __init__(self, path: Path = DAMPER_FMU3, start: Optional[dict] = None):
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=md.modelExchange.modelIdentifier, instanceName="damper")
        self.fmu.instantiate(logMessage=lambda env, status, category, message: print(message.decode()))
        self.fmu.enterInitializationMode(startTime=0.0)
        for name, value in (start or coupled.DAMPER_START).items():
            self.fmu.setFloat64([self.vr[name]], [value])
        self.fmu.exitInitializationMode()
        self._update()
        self.fmu.enterContinuousTimeMode()
        self.nx, self.nz = md.numberOfContinuousStates, md.numberOfEventIndicators
        self.base, self.outputs = [self.vr["base_displacement"], self.vr["base_velocity"]], [self.vr[n] for n in OUTPUTS]
        self.nominals = np.empty(self.nx)
        self.fmu.getNominalsOfContinuousStates(_pointer(self.nominals), self.nx)

    def _update(self) -> None:
        while True:
            need_update, terminate = self.fmu.updateDiscreteStates()[:2]
            if terminate:
                raise RuntimeError("the damper FMU asked to terminate (see its log)")
            if not need_update:
                return

    def load(self, t: float, X: float, V: float, x: np.ndarray) -> None:
        self.fmu.setTime(t)
        self.fmu.setFloat64(self.base, [X, V])
        self.fmu.setContinuousStates(_pointer(np.ascontiguousarray(x, dtype=float)), self.nx)

    def states(self) -> np.ndarray:
        x = np.empty(self.nx)
        self.fmu.getContinuousStates(_pointer(x), self.nx)
        return x

    def derivatives(self) -> np.ndarray:
        dx = np.empty(self.nx)
        self.fmu.getContinuousStateDerivatives(_pointer(dx), self.nx)
        return dx

    def indicators(self) -> np.ndarray:
        z = np.empty(self.nz)
        self.fmu.getEventIndicators(_pointer(z), self.nz)
        return z

    def event(self) -> np.ndarray:
        """The event update at the loaded instant; the states after it."""
        self.fmu.enterEventMode()
        self._update()
        self.fmu.enterContinuousTimeMode()
        return self.states()


def simulate(stop: float = coupled.STOP_TIME, rtol: float = 1e-10, grid: float = 5e-4) -> dict:
    """The monolithic run to ``stop`` (s) at relative tolerance ``rtol``, sampled every ``grid`` s:
    the floor's and the damper's outputs, the ledger residual ``R``, the work and the cost."""
    M_s, K_s, C_s = FLOOR["M_s"], FLOOR["K_s"], FLOOR["C_s"]
    ground = GroundMotion(FLOOR["pga"])
    damper = DamperME()
    u0, v0, _ = ground(0.0)
    state = np.concatenate([[u0, v0, 0.0, 0.0], damper.states()])  # X, X', W_ground, D_s, damper
    # Absolute tolerances from the sizes of the floor's states (mm, cm/s, 10 mJ) and the FMU's nominals.
    atol = rtol * np.concatenate([[1e-3, 1e-2, 1e-2, 1e-2], damper.nominals])

    def rhs(t, s):
        damper.load(t, s[0], s[1], s[4:])
        force = damper.fmu.getFloat64([damper.vr["base_force"]])[0]
        u_g, v_g, _ = ground(t)
        spring = K_s * (s[0] - u_g) + C_s * (s[1] - v_g)
        return np.concatenate([[s[1], (force - spring) / M_s, -spring * v_g, C_s * (s[1] - v_g) ** 2],
                               damper.derivatives()])

    def indicators(t, s):
        damper.load(t, s[0], s[1], s[4:])
        return damper.indicators()

    events = [lambda t, s, i=i: indicators(t, s)[i] for i in range(damper.nz)]
    for event in events:
        event.terminal = True
    t, rows, n_events, started = 0.0, [], 0, time.process_time()
    while t < stop:
        start = indicators(t, state)
        sol = solve_ivp(rhs, (t, stop), state, method="DOP853", rtol=rtol, atol=atol, events=events, dense_output=True)
        end = sol.t[-1]
        for tk in np.arange(np.ceil(t / grid - 1e-9), np.floor(end / grid + 1e-9) + 1) * grid:
            if not rows or tk > rows[-1][0]:
                sk = sol.sol(tk)
                damper.load(tk, sk[0], sk[1], sk[4:])
                rows.append([tk, *sk[:4], *ground(tk)[:2], *damper.fmu.getFloat64(damper.outputs)])
        if sol.status != 1:
            break
        fired = min((times[0], i) for i, times in enumerate(sol.t_events) if len(times))[1]
        t, state = _past_crossing(sol, end, lambda tt, ss: indicators(tt, ss)[fired], start[fired])
        damper.load(t, state[0], state[1], state[4:])
        state[4:] = damper.event()
        n_events += 1
    cpu = time.process_time() - started
    impacts = damper.fmu.getInt32([damper.vr["impact_count"]])[0]
    damper.fmu.terminate()
    damper.fmu.freeInstance()
    data = dict(zip(("time", "X", "V", "work_ground", "dissipated_floor", "u_g", "v_g") + OUTPUTS, np.array(rows).T))
    data["drift"] = data["X"] - data["u_g"]
    floor_energy = 0.5 * M_s * data["V"] ** 2 + 0.5 * K_s * data["drift"] ** 2
    stored = floor_energy + coupled.stored_energy(data, data["X"])
    data["residual"] = (stored - stored[0]) - data["work_ground"] + data["dissipated_floor"] + data["energy_dissipated"]
    data.update(events=n_events, impacts=impacts, cpu=cpu)
    return data


def _past_crossing(sol, t: float, indicator, start: float) -> tuple[float, np.ndarray]:
    """The first instant from ``t`` on (the root solve_ivp found) where ``indicator`` is non-zero and
    has left the sign of its value ``start`` at the segment's start (any sign, if that was 0: solve_ivp
    takes a zero there for a crossing), and the state there: the FMU then sees the crossing it is
    asked about, and the restart does not find it again."""
    step = np.spacing(max(abs(t), 1.0))
    for _ in range(64):  # the root is within a few ulps of the crossing
        state = sol.sol(t)
        z = indicator(t, state)
        if z != 0.0 and (start == 0.0 or (z > 0.0) != (start > 0.0)):
            return t, state
        t, step = t + step, 2.0 * step
    raise RuntimeError(f"no sign change of the event indicator after t = {t!r} s")


def compare_with_cosimulation(mono: dict, steps=STEPS, stop: float = coupled.STOP_TIME, horizon: float = 1.0) -> list[dict]:
    """The co-simulation of ``hosts/coupled.py`` (OSP libcosim) at each step against ``mono``: the
    largest difference of the floor's drift up to ``horizon`` (s) and over the whole run, when it
    first exceeds 1 % of the peak drift, and the co-simulation's ledger residual (its coupling error).
    Each impact amplifies a difference (docs/model.md section 8), so only the first stretch of the
    run shows the order of the coupling error; later the trajectories part, whatever the step."""
    table, peak = [], np.max(np.abs(mono["drift"]))
    for step in steps:
        run = coupled.run_osp(step, stop)
        error = np.abs(run.structure["relative_displacement"] - np.interp(run.time, mono["time"], mono["drift"]))
        apart = error > 0.01 * peak
        table.append({"step": step, "drift_error": float(np.max(error[run.time <= horizon + 1e-12])),
                      "drift_error_all": float(np.max(error)),
                      "parted_at": float(run.time[np.argmax(apart)]) if apart.any() else np.inf,
                      "residual": coupled.ledger(run).max_residual, "impacts": int(run.damper["impact_count"][-1])})
    return table


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stop", type=float, default=coupled.STOP_TIME, help="end time (s)")
    parser.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance of solve_ivp")
    parser.add_argument("--no-cosim", action="store_true", help="skip the co-simulation comparison")
    args = parser.parse_args(argv)
    mono = simulate(args.stop, args.rtol)
    peak = np.max(np.abs(mono["drift"]))
    print(f"monolithic (solve_ivp DOP853, rtol {args.rtol:g}): {args.stop:g} s in {mono['cpu']:.1f} s CPU, "
          f"{mono['events']} events, {mono['impacts']} impacts; peak floor drift {1e3 * peak:.4f} mm")
    print(f"ledger: ground work {mono['work_ground'][-1]:.6f} J, dissipated floor {mono['dissipated_floor'][-1]:.6f} J, "
          f"damper {mono['energy_dissipated'][-1]:.6f} J; residual max {np.max(np.abs(mono['residual'])):.2e} J")
    if args.no_cosim:
        return 0
    print("co-simulation (hosts/coupled.py, OSP libcosim) against it:")
    print(f"{'step (ms)':>9s} {'max |drift - mono| to 1 s (mm)':>31s} {'to the end (mm)':>16s} "
          f"{'1 % of peak at (s)':>19s} {'ledger |R| (J)':>15s} {'impacts':>7s}")
    for row in compare_with_cosimulation(mono, stop=args.stop):
        print(f"{row['step'] * 1e3:9.2f} {1e3 * row['drift_error']:31.3e} {1e3 * row['drift_error_all']:16.3e} "
              f"{row['parted_at']:19.3f} {row['residual']:15.3e} {row['impacts']:7d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
