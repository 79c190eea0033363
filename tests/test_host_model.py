"""A native (C) host, and a host model that plugs the damper into a primary structure.

1. ``hosts/native_host.c`` is built here with the system C compiler against the FMI headers
   and loads ``binaries/linux64/PiezoImpactDamper.so`` from the extracted FMU: the project's
   loader, which finds a Python itself. pythonfmu's own binary cannot be loaded by such a host
   (proved); the FMU can: in a bare environment (only ``PATH``, no ``LD_PRELOAD``,
   ``PYTHONHOME`` or ``PYTHONPATH``) the nominal case (docs/model.md section 7, 2 s at a 1 ms step)
   runs cleanly, exits with status 0 and nothing on stderr, and its results equal fmpy's bit
   for bit. ``tests/test_loader.py`` tests the loader itself.
2. ``hosts/system/OspSystemStructure.xml`` couples ``PrimaryStructure.fmu`` (an SDOF floor on a
   synthetic ground-motion record, built here from ``hosts/primary_structure.py``) with the
   damper both ways, in OSP libcosim; the SSP version runs in ecos and gives the same result.
   The coupled run's energy ledger closes to the co-simulation coupling error, which shrinks at
   first order with the communication step, and the response converges.
"""

from __future__ import annotations

import os
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from crosscheck import importers, scenario  # noqa: E402
from hosts import coupled, native  # noqa: E402

FMU = REPO / "fmus" / "PiezoImpactDamper.fmu"
NOMINAL_STOP, NOMINAL_STEP = 2.0, 1e-3


# -- the C host ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    return native.build(tmp_path_factory.mktemp("native") / "native_host")


def test_c_host_builds_with_the_system_compiler(host):
    assert host.is_file() and os.access(host, os.X_OK)
    assert (native.fmi_headers() / "fmi2FunctionTypes.h").is_file()


def test_c_host_cannot_load_pythonfmus_own_binary(host, tmp_path):
    """The reason for the loader: pythonfmu's binary calls the Python C API but links no
    libpython, so a native host cannot load it."""
    import zipfile

    with zipfile.ZipFile(FMU) as archive:
        archive.extractall(tmp_path / "fmu")
    binaries = tmp_path / "fmu" / "binaries" / "linux64"
    (binaries / "PiezoImpactDamper.pythonfmu.so").replace(binaries / "PiezoImpactDamper.so")
    completed = subprocess.run([str(host), str(tmp_path / "fmu"), str(tmp_path / "out.csv"), "--stop", "0.01"],
                               capture_output=True, text=True, env=native.environment(), timeout=60)
    assert completed.returncode == 1
    assert "native_host: cannot load " in completed.stderr and "undefined symbol" in completed.stderr


@lru_cache(maxsize=None)
def fmpy_nominal() -> importers.Result:
    return importers.run_fmpy(FMU, times=scenario.grid(0.0, NOMINAL_STOP, NOMINAL_STEP), inputs={},
                              start_values={})


def test_c_host_runs_the_nominal_case_cleanly_in_a_bare_environment_and_equals_fmpy(host, tmp_path):
    env = native.environment()
    assert not {"LD_PRELOAD", "PYTHONHOME", "PYTHONPATH", "PIEZO_FMU_PYTHON"} & set(env)
    out = tmp_path / "nominal.csv"
    completed = native.run(FMU, out, ["--stop", repr(NOMINAL_STOP), "--step", repr(NOMINAL_STEP)],
                           executable=host, env=env)
    assert completed.returncode == 0  # a clean exit: no crash in the interpreter's teardown
    assert completed.stderr == "" and completed.stdout == ""
    time, outputs = scenario.read_csv(out)
    reference = fmpy_nominal()
    assert list(outputs) == list(reference.outputs)
    comparison = scenario.compare(time, outputs, reference.time, reference.outputs, rel_tol=0.0)
    assert comparison.all_bit_identical, comparison.report()
    assert outputs["impact_count"][-1] > 0 and outputs["main_displacement"][0] == 0.01


def test_c_host_runs_the_fmi3_fmu_in_a_bare_environment_and_equals_fmpy(host, tmp_path):
    """The FMI 3.0 FMU, through its own loader, gives the FMI 2.0 FMU's bits in fmpy."""
    out = tmp_path / "nominal3.csv"
    native.run(FMU.with_name("PiezoImpactDamper3.fmu"), out,
               ["--stop", repr(NOMINAL_STOP), "--step", repr(NOMINAL_STEP)], executable=host)
    time, outputs = scenario.read_csv(out)
    reference = fmpy_nominal()
    comparison = scenario.compare(time, outputs, reference.time, reference.outputs, rel_tol=0.0)
    assert comparison.all_bit_identical, comparison.report()


def test_c_host_runs_the_cross_check_scenario(host, tmp_path):
    out = tmp_path / "xc.csv"
    args = ["--stop", repr(scenario.STOP_TIME), "--step", "0.001", "--in", str(scenario.IN_CSV), "--set", "p0=0",
            "--set", "q0=0"]
    native.run(FMU, out, args, executable=host)
    time, outputs = scenario.read_csv(out)
    ref_time, ref = scenario.read_reference()
    assert scenario.compare(time, outputs, ref_time, ref).passed
    # Bit for bit what fmpy gives on this machine (the reference's bits are those of the machine
    # that wrote it).
    fmpy_run = importers.run("fmpy", FMU)
    comparison = scenario.compare(time, outputs, fmpy_run.time, fmpy_run.outputs)
    assert comparison.all_bit_identical, comparison.report()


@pytest.mark.parametrize("start_value, words", [("p0=0", "q0 = 0.01 m starts the impact mass outside the gap"),
                                                ("m=-1", "m = -1.0 kg is out of range")])
def test_c_host_reports_fmu_errors_with_status_1(host, tmp_path, start_value, words):
    """Invalid start values (q0 outside the gap, a negative mass) are an FMU error, not a crash,
    and never NaN output with exit status 0: the host treats any status but OK as an error."""
    with pytest.raises(subprocess.CalledProcessError) as failure:
        native.run(FMU, tmp_path / "bad.csv", ["--stop", "0.01", "--set", start_value], executable=host)
    assert failure.value.returncode == 1 and "fmi2ExitInitializationMode returned Error (3)" in failure.value.stderr
    assert f"invalid start values: {words}" in failure.value.stderr  # the FMU's own message


def test_c_host_refusals_each_return_error_and_the_reset_instance_gives_a_fresh_ones_bits(host, tmp_path):
    """``--refusals`` (every call the FMU must refuse, then Reset) on Linux, as tests/test_windows.py
    runs it on Windows: the host exits 0 only if each refusal returned Error and all else OK."""
    fresh, after_reset = tmp_path / "fresh.csv", tmp_path / "after_reset.csv"
    args = ["--stop", "0.5", "--step", repr(NOMINAL_STEP)]
    native.run(FMU, fresh, args, executable=host)
    completed = native.run(FMU, after_reset, [*args, "--refusals"], executable=host)
    assert completed.stderr.count("native_host: refused as it must be (Error): ") == 16
    assert after_reset.read_bytes() == fresh.read_bytes()


def test_c_host_two_instances_in_two_threads_give_the_bits_of_one_alone(host, tmp_path):
    alone, threads = tmp_path / "alone.csv", tmp_path / "threads.csv"
    args = ["--stop", "0.5", "--step", repr(NOMINAL_STEP)]
    native.run(FMU, alone, args, executable=host)
    native.run(FMU.with_name("PiezoImpactDamper3.fmu"), threads, [*args, "--threads", "2"], executable=host)
    for k in (1, 2):
        assert Path(f"{threads}.{k}").read_bytes() == alone.read_bytes()


# -- the host model ------------------------------------------------------------------------------------

CONVERGENCE_STEPS = (4e-3, 2e-3, 1e-3, 5e-4)


@lru_cache(maxsize=None)
def osp(step: float = coupled.STEP_SIZE, with_damper: bool = True) -> coupled.Run:
    return coupled.run_osp(step, coupled.STOP_TIME, with_damper)


@lru_cache(maxsize=None)
def ecos_ssp() -> coupled.Run:
    return coupled.run_ssp_ecos(coupled.STEP_SIZE, coupled.STOP_TIME)


def test_structure_alone_follows_its_record_and_keeps_its_ledger():
    bare = osp(with_damper=False)
    s = bare.structure
    assert np.isclose(np.max(np.abs(s["ground_acceleration"])), 1.0, rtol=1e-9)  # PGA of the record
    assert np.all(s["work_device"] == 0.0)
    # Runge-Kutta's own ledger error, far below the coupling error of the coupled runs
    assert abs(s["energy_balance_error"][-1]) < 1e-9 * s["work_ground"][-1]


def test_coupled_osp_run_couples_both_ways_and_damps_the_floor():
    run, bare = osp(), osp(with_damper=False)
    assert len(run.time) == 5001 and run.time[-1] == coupled.STOP_TIME
    s, d = run.structure, run.damper
    # the damper's base follows the floor and its force acts back on it
    assert d["impact_count"][-1] > 20
    assert np.max(np.abs(s["work_device"])) > 0.01
    peak_with = np.max(np.abs(s["relative_displacement"]))
    peak_without = np.max(np.abs(bare.structure["relative_displacement"]))
    assert peak_with < 0.7 * peak_without
    assert np.sqrt(np.mean(s["relative_displacement"] ** 2)) < 0.7 * np.sqrt(
        np.mean(bare.structure["relative_displacement"] ** 2))


def test_coupled_energy_ledger_closes_to_the_coupling_error():
    book = coupled.ledger(osp())
    # each FMU's own ledger closes to its integrator's error ...
    assert abs(book.damper_error) < 1e-12 and abs(book.structure_error) < 1e-9
    # ... and the system's closes to the interface error of the co-simulation: small, and much
    # larger than those (so it is the coupling that shows here, not an integrator)
    assert book.relative_residual < 0.01
    assert book.max_residual > 1e3 * (abs(book.damper_error) + abs(book.structure_error))
    assert book.work_ground > 0.1 and book.dissipated_damper > 0.02


def test_coupled_run_converges_as_the_step_shrinks():
    runs = [osp(step) for step in CONVERGENCE_STEPS]
    residuals = [coupled.ledger(run).max_residual for run in runs]
    # first order: the ledger residual halves (at least roughly) with the step
    for coarse, fine in zip(residuals[:-1], residuals[1:]):
        assert fine < coarse / 1.4, residuals
    assert residuals[-1] < residuals[0] / 6, residuals
    # the trajectory converges at first order over the first second (11 impacts), before the
    # impacts' sensitivity takes over: successive differences halve
    differences = []
    for coarse, fine in zip(runs[:-1], runs[1:]):
        a, b = coupled.on_common_grid(coarse, fine, "relative_displacement")
        n = int(round(1.0 / coarse.step)) + 1
        differences.append(np.max(np.abs(a[:n] - b[:n])))
    for coarse, fine in zip(differences[:-1], differences[1:]):
        assert 1.6 < coarse / fine < 2.5, differences
    # and the global measures settle
    peaks = [np.max(np.abs(run.structure["relative_displacement"])) for run in runs]
    assert abs(peaks[-1] - peaks[-2]) < 0.02 * peaks[-1], peaks


def test_ssp_in_ecos_runs_the_same_system():
    ecos, libcosim = ecos_ssp(), osp()
    assert len(ecos.time) == len(libcosim.time)
    assert ecos.damper["main_displacement"][0] == 0.0  # the ssv's p0 = 0 was applied
    assert ecos.damper["impact_count"][-1] > 20
    assert coupled.ledger(ecos).relative_residual < 0.01
    for which in ("structure", "damper"):
        a, b = getattr(libcosim, which), getattr(ecos, which)
        comparison = scenario.compare(ecos.time, b, libcosim.time, a)
        assert comparison.all_bit_identical, (
            f"{which}: ecos SSP against libcosim OSP\n{comparison.report()}\necos adds the step to its time at "
            "every step; both FMUs must take each step's end to the whole nanosecond (crosscheck/ReadMe.md)")
