"""The host model: the piezo-impact damper mounted on an SDOF floor under a ground-motion record.

    python hosts/coupled.py [--figure PNG]      # default: hosts/coupled_response.png

builds ``PrimaryStructure.fmu`` (into ``build/hosts``), runs the OSP system structure
``hosts/system/OspSystemStructure.xml`` in OSP libcosim (with the damper) and
``hosts/system/bare/OspSystemStructure.xml`` (the floor alone), runs the SSP version
(``hosts/system/ssp``) in ecos, prints the energy ledger and a step-size convergence table, and
draws ``coupled_response.png`` (the floor's drift with and without the damper).

Coupling (both masters run a fixed-step Jacobi scheme): at each communication point ``t_k`` the
floor's absolute displacement ``X_k`` and velocity ``V_k`` are set as the damper's
``base_displacement`` and ``base_velocity``, and the damper's ``base_force`` ``F_k`` as the floor's
``damper_force``; then both step to ``t_{k+1}``. Over the step the damper moves its base as
``X_k + V_k (t - t_k)`` (its input hold) and the floor holds ``F_k``.

Energy ledger of the coupled system (absolute, inertial frame): with ``E_s`` the floor's energy
and ``E_d`` the damper's (kinetic energy of both bodies, with the barrier tip mass ``M_eq``
moving with the impact mass during a contact, plus ``K (p - y)^2 / 2`` and
``K_eq delta^2 / 2``), the residual

    R = (E_s + E_d) - (E_s + E_d)(0) - W_ground + D_s + D_d

would be zero (to the integrators' errors) in a monolithic simulation. In the co-simulation it
equals the interface work mismatch: the work ``work_device = int F_k X' dt`` the damper does on
the floor (floor side, force held) plus the work its base does on the damper (damper side,
base on the ramp, and a jump of the base to ``X_{k+1}`` at each communication point counted as
work). Both sides are first-order holds, so ``R`` is a coupling error of order ``h``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from crosscheck.importers import TimeSeries, output_variables, quiet_libcosim  # noqa: E402
from hosts import build_structure  # noqa: E402

DAMPER_FMU = REPO / "fmus" / "PiezoImpactDamper.fmu"
OSP_COUPLED = HERE / "system" / "OspSystemStructure.xml"
OSP_BARE = HERE / "system" / "bare" / "OspSystemStructure.xml"
SSP_DIR = HERE / "system" / "ssp"
STOP_TIME = 5.0
STEP_SIZE = 1e-3
#: The damper's start values in the host model (at rest at the floor's origin).
DAMPER_START = {"p0": 0.0, "q0": 0.0}
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"


@dataclass
class Run:
    """Time series of one coupled (or bare) run."""

    master: str
    step: float
    time: np.ndarray
    structure: dict[str, np.ndarray]
    damper: Optional[dict[str, np.ndarray]]
    wall_time: float


def structure_fmu() -> Path:
    return build_structure.build()


# -- OSP libcosim -------------------------------------------------------------------------------

def _staged_osp(source: Path, step: float, scratch: Path, damper: Optional[Path] = None) -> Path:
    """A copy of an OSP system structure with absolute FMU paths and the given base step
    (and, if given, another damper FMU)."""
    ET.register_namespace("", OSP_NS)
    tree = ET.parse(source)
    root = tree.getroot()
    root.find(f"{{{OSP_NS}}}BaseStepSize").text = repr(step)
    for simulator in root.iter(f"{{{OSP_NS}}}Simulator"):
        path = (source.parent / simulator.get("source")).resolve()
        if damper is not None and simulator.get("name") == "damper":
            path = Path(damper).resolve()
        simulator.set("source", path.as_uri())
    staged = scratch / "OspSystemStructure.xml"
    tree.write(staged, xml_declaration=True, encoding="utf-8")
    return staged


def run_osp(step: float = STEP_SIZE, stop: float = STOP_TIME, with_damper: bool = True,
            damper: Path = DAMPER_FMU) -> Run:
    """Run the OSP system structure in libcosim at the base step ``step`` (s) up to ``stop``."""
    from libcosimpy.CosimExecution import CosimExecution

    quiet_libcosim()
    structure = structure_fmu()
    step_ns = int(round(step * 1e9))
    n = int(round(stop * 1e9)) // step_ns
    with tempfile.TemporaryDirectory(prefix="piezo_osp_") as scratch:
        staged = _staged_osp(OSP_COUPLED if with_damper else OSP_BARE, step, Path(scratch), damper)
        started = time.perf_counter()
        execution = CosimExecution.from_osp_config_file(str(staged))
        slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
        variables = {slaves["structure"]: output_variables(structure)}
        if with_damper:
            variables[slaves["damper"]] = output_variables(damper)
        recorder = TimeSeries(execution, variables, n + 1)
        if not execution.simulate_until(n * step_ns):
            raise RuntimeError(f"libcosim failed: {execution.status()}")
        times, floor = recorder.samples(slaves["structure"], n + 1)
        damper = recorder.samples(slaves["damper"], n + 1)[1] if with_damper else None
        wall = time.perf_counter() - started
        del execution
    return Run("libcosim", step, np.array(times) / 1e9, floor, damper, wall)


# -- SSP in ecos ----------------------------------------------------------------------------------

def stage_ssp(dest: Path, damper: Path = DAMPER_FMU) -> Path:
    """An SSP archive (``.ssp``) of the host model: the ssd, its ssv and both FMUs."""
    dest = Path(dest)
    with zipfile.ZipFile(dest, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.write(SSP_DIR / "SystemStructure.ssd", "SystemStructure.ssd")
        for ssv in sorted((SSP_DIR / "ssv").glob("*.ssv")):
            archive.write(ssv, f"ssv/{ssv.name}")
        archive.write(structure_fmu(), "resources/PrimaryStructure.fmu")
        archive.write(damper, "resources/PiezoImpactDamper.fmu")
    return dest


def run_ssp_ecos(step: float = STEP_SIZE, stop: float = STOP_TIME, damper: Path = DAMPER_FMU) -> Run:
    """Run the SSP version of the host model in ecos at the fixed step ``step``."""
    from ecospy import EcosLib, EcosSimulation

    EcosLib.set_log_level("warn")
    structure_outs = output_variables(structure_fmu())
    damper_outs = output_variables(damper)
    n = int(round(stop * 1e9)) // int(round(step * 1e9))
    with tempfile.TemporaryDirectory(prefix="piezo_ssp_") as scratch:
        archive = stage_ssp(Path(scratch) / "PiezoHost.ssp", damper)
        started = time.perf_counter()
        simulation = EcosSimulation(ssp_path=str(archive), step_size=step)
        try:
            if not simulation.init(parameter_set="initialValues"):
                raise RuntimeError(f"ecos could not initialize the SSP: {EcosLib.get_last_error()}")

            def read(instance, outs):
                return [simulation.get_integer(f"{instance}::{name}") if kind == "Integer"
                        else simulation.get_real(f"{instance}::{name}") for name, _, kind in outs]

            times = [simulation.get_time()]
            rows_s, rows_d = [read("structure", structure_outs)], [read("damper", damper_outs)]
            for _ in range(n):
                simulation.step(1)
                times.append(simulation.get_time())
                rows_s.append(read("structure", structure_outs))
                rows_d.append(read("damper", damper_outs))
            simulation.terminate()
        finally:
            simulation.free()
        wall = time.perf_counter() - started

    def columns(rows, outs):
        return {name: np.array([r[j] for r in rows], dtype=np.int64 if kind == "Integer" else float)
                for j, (name, _, kind) in enumerate(outs)}

    return Run("ecos", step, np.array(times), columns(rows_s, structure_outs), columns(rows_d, damper_outs), wall)


# -- the energy ledger ----------------------------------------------------------------------------

def damper_energy(run: Run) -> np.ndarray:
    """The damper's stored energy at every sample, rebuilt from its outputs (see module doc)."""
    from piezo_fmu import Parameters
    from piezo_fmu.model.barrier import derive_barrier

    params = Parameters(**DAMPER_START)
    barrier = derive_barrier(params)
    d, s = run.damper, run.structure
    in_contact = (d["deflection_left"] > 0.0) | (d["deflection_right"] > 0.0)
    m_main = np.where(in_contact, params.M - barrier.M_eq, params.M)
    m_impact = np.where(in_contact, params.m + barrier.M_eq, params.m)
    kinetic = 0.5 * (m_main * d["main_velocity"] ** 2 + m_impact * d["impactor_velocity"] ** 2)
    # The damper's base at the end of step k is on its ramp: X_k + V_k h (not yet X_{k+1}).
    base = np.empty_like(run.time)
    base[0] = s["displacement"][0]
    base[1:] = s["displacement"][:-1] + s["velocity"][:-1] * np.diff(run.time)
    deflection = d["deflection_left"] + d["deflection_right"]
    potential = 0.5 * params.K * (d["main_displacement"] - base) ** 2 + 0.5 * barrier.K_eq * deflection**2
    return kinetic + potential


@dataclass
class Ledger:
    """Energy ledger of a coupled run at its end time (J)."""

    work_ground: float  # work of the ground on the floor
    dissipated_structure: float
    dissipated_damper: float
    stored: float  # E_s + E_d at the end
    stored_initial: float
    residual: np.ndarray  # R(t)
    structure_error: float  # the floor FMU's own ledger residual (Runge-Kutta) at the end
    damper_error: float  # the damper FMU's own ledger residual at the end

    @property
    def final_residual(self) -> float:
        return float(self.residual[-1])

    @property
    def max_residual(self) -> float:
        return float(np.max(np.abs(self.residual)))

    @property
    def relative_residual(self) -> float:
        """``max |R|`` over the run relative to the energy the ground put in."""
        return self.max_residual / max(abs(self.work_ground), 1e-300)


def ledger(run: Run) -> Ledger:
    s, d = run.structure, run.damper
    stored = s["energy"] + damper_energy(run)
    residual = (stored - stored[0]) - s["work_ground"] + s["energy_dissipated"] + d["energy_dissipated"]
    return Ledger(work_ground=float(s["work_ground"][-1]), dissipated_structure=float(s["energy_dissipated"][-1]),
                  dissipated_damper=float(d["energy_dissipated"][-1]), stored=float(stored[-1]),
                  stored_initial=float(stored[0]), residual=residual,
                  structure_error=float(s["energy_balance_error"][-1]),
                  damper_error=float(d["energy_balance_error"][-1]))


# -- convergence ----------------------------------------------------------------------------------

def convergence(steps=(4e-3, 2e-3, 1e-3, 5e-4), stop: float = STOP_TIME) -> list[dict]:
    """Ledger residual and response measures of the OSP run at each communication step."""
    table = []
    for step in steps:
        run = run_osp(step, stop)
        book = ledger(run)
        drift = run.structure["relative_displacement"]
        table.append({
            "step": step,
            "run": run,
            "max_residual": book.max_residual,
            "relative_residual": book.relative_residual,
            "work_ground": book.work_ground,
            "dissipated_damper": book.dissipated_damper,
            "peak_drift": float(np.max(np.abs(drift))),
            "rms_drift": float(np.sqrt(np.mean(drift**2))),
            "impacts": int(run.damper["impact_count"][-1]),
            "wall_time": run.wall_time,
        })
    return table


def on_common_grid(coarse: Run, fine: Run, name: str, which: str = "structure") -> tuple[np.ndarray, np.ndarray]:
    """``name`` of both runs at the coarse run's points (the fine grid contains them)."""
    ratio = int(round(coarse.step / fine.step))
    a = getattr(coarse, which)[name]
    b = getattr(fine, which)[name][::ratio]
    return a, b[: len(a)]


# -- the figure -----------------------------------------------------------------------------------

def figure(coupled: Run, bare: Run, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].plot(bare.time, bare.structure["ground_acceleration"], color="0.4", lw=0.8)
    axes[0].set_ylabel("ground accel.\n(m/s$^2$)")
    axes[0].set_title("SDOF floor (20 kg, 5.03 Hz, 2 % damping) under a synthetic record, PGA 1 m/s$^2$")
    axes[1].plot(bare.time, 1e3 * bare.structure["relative_displacement"], color="tab:red", lw=0.9,
                 label="floor alone")
    axes[1].plot(coupled.time, 1e3 * coupled.structure["relative_displacement"], color="tab:blue", lw=0.9,
                 label="with the piezo-impact damper")
    axes[1].set_ylabel("floor drift\nX - u$_g$ (mm)")
    axes[1].legend(loc="upper right", fontsize=8)
    voltage = coupled.damper["voltage_left"] + coupled.damper["voltage_right"]
    axes[2].plot(coupled.time, voltage, color="tab:green", lw=0.7)
    axes[2].set_ylabel("barrier voltage\n(V)")
    axes[2].set_xlabel("time (s)")
    fig.text(0.01, 0.005, f"OSP libcosim, fixed step {coupled.step * 1e3:g} ms; "
             f"{int(coupled.damper['impact_count'][-1])} impacts", fontsize=7, color="0.3")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--figure", type=Path, default=HERE / "coupled_response.png")
    args = parser.parse_args(argv)

    coupled, bare = run_osp(), run_osp(with_damper=False)
    book = ledger(coupled)
    peak_bare = np.max(np.abs(bare.structure["relative_displacement"]))
    peak_coupled = np.max(np.abs(coupled.structure["relative_displacement"]))
    print(f"OSP libcosim, {STOP_TIME:g} s at {STEP_SIZE * 1e3:g} ms: peak floor drift {1e3 * peak_bare:.3f} mm alone, "
          f"{1e3 * peak_coupled:.3f} mm with the damper ({int(coupled.damper['impact_count'][-1])} impacts)")
    print(f"ledger: ground work {book.work_ground:.6f} J, dissipated floor {book.dissipated_structure:.6f} J, "
          f"damper {book.dissipated_damper:.6f} J, stored {book.stored:.6f} J; "
          f"coupling residual max {book.max_residual:.3e} J ({book.relative_residual:.2e} of the ground work)")
    print("convergence (OSP libcosim):")
    print(f"{'step (ms)':>9s} {'max |R| (J)':>12s} {'|R|/W_g':>9s} {'peak drift (mm)':>16s} "
          f"{'rms drift (mm)':>15s} {'D_damper (J)':>13s} {'impacts':>7s}")
    for row in convergence():
        print(f"{row['step'] * 1e3:9.2f} {row['max_residual']:12.3e} {row['relative_residual']:9.2e} "
              f"{1e3 * row['peak_drift']:16.6f} {1e3 * row['rms_drift']:15.6f} {row['dissipated_damper']:13.6f} "
              f"{row['impacts']:7d}")
    ecos_run = run_ssp_ecos()
    ecos_book = ledger(ecos_run)
    print(f"SSP in ecos: peak floor drift {1e3 * np.max(np.abs(ecos_run.structure['relative_displacement'])):.3f} mm, "
          f"{int(ecos_run.damper['impact_count'][-1])} impacts, coupling residual max {ecos_book.max_residual:.3e} J")
    path = figure(coupled, bare, args.figure)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
