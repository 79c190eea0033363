"""The FMUs' own binary, the loader (``src/piezo_fmu/build/loader``): drop-in and conformant.

1. Any native host loads the FMUs with no launcher: the C host (``hosts/native_host.c``) runs
   them in a bare environment (``tests/test_host_model.py`` shows the damper's nominal case bit
   for bit against fmpy). With no usable Python, instantiation fails with a message that says
   what was tried and what to set, and the host exits cleanly; a hanging interpreter does not
   hang it.
2. A refused call returns Error from that very call, with the refusal's own text, in FMI 2.0
   and 3.0, from the C API and in fmpy; any other exception stays Fatal. ``Reset`` brings the
   instance back, however many calls were refused.
3. An FMI 2.0 and an FMI 3.0 FMU in one native process share one interpreter.
4. The loader exports the whole FMI API of its version and is byte-reproducible.

The FMI 3.0 FMU of the project does not exist yet: tiny FMI 2.0 and 3.0 FMUs with the same
behaviour (``tests/loader_slaves.py``) are built here with pythonfmu and pythonfmu3 and get the
loader as the project's builds give it.
"""

from __future__ import annotations

import ctypes
import subprocess
import sys
import time
import zipfile
from importlib.metadata import distribution
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.fmi3 import FMU3Slave

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hosts import native  # noqa: E402
from piezo_fmu.build import archive as fmu_archive  # noqa: E402
from piezo_fmu.build.loader import (BINARIES, LIBRARY_SUFFIX, LINUX_BINARIES, PLATFORMS, REAL_SUFFIXES,  # noqa: E402
                                  compile_loader, install_loader)
from piezo_fmu.build.loader.generate import api, pythonfmu3_unimplemented  # noqa: E402
from tests.loader_slaves import SLAVE_2, SLAVE_3, SOURCE_2, SOURCE_3  # noqa: E402

FMU = REPO / "fmus" / "PiezoImpactDamper.fmu"
IDENTIFIER = {2: SLAVE_2, 3: SLAVE_3}
OK, ERROR, FATAL = 0, 3, 4  # the same numbers in FMI 2.0 and 3.0
ADVICE = "Set PIEZO_FMU_PYTHON=/path/to/python"


def build_tiny(version: int, folder: Path, mend_references: bool = True) -> Path:
    """The tiny FMU of FMI ``version`` with the loader, pythonfmu's binary mended as the build does."""
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / f"loadertest{version}.py"
    script.write_text(SOURCE_2 if version == 2 else SOURCE_3)
    subprocess.run([sys.executable, "-m", "pythonfmu" if version == 2 else "pythonfmu3", "build", "-f", str(script),
                    "-d", str(folder)], check=True, capture_output=True, timeout=120)
    with zipfile.ZipFile(folder / f"{IDENTIFIER[version]}.fmu") as archive:
        files = {name: archive.read(name) for name in archive.namelist() if not name.endswith("/")}
    binary = f"{LINUX_BINARIES[version]}/{IDENTIFIER[version]}.so"
    files[binary] = fmu_archive.drop_exit_unload(files[binary])
    if mend_references:
        files[binary] = fmu_archive.keep_references_on_exception(files[binary])
    dest = folder / f"{IDENTIFIER[version]}_with_loader.fmu"
    dest.write_bytes(fmu_archive.deterministic_zip(install_loader(files, version, IDENTIFIER[version])))
    return dest


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> dict[int, Path]:
    folder = tmp_path_factory.mktemp("tiny")
    return {version: build_tiny(version, folder / f"fmi{version}") for version in (2, 3)}


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    return native.build(tmp_path_factory.mktemp("native") / "native_host")


def extract(fmu: Path, folder: Path) -> Path:
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(folder)
    return folder


def run_host(host: Path, fmu: Path, tmp_path: Path, args=(), env=None) -> subprocess.CompletedProcess:
    """The C host on ``fmu`` (bare environment unless ``env``); its exit status is not checked."""
    fmu_dir = extract(fmu, tmp_path / "fmu")
    return subprocess.run([str(host), str(fmu_dir), str(tmp_path / "out.csv"), *args], capture_output=True, text=True,
                          env=native.environment() if env is None else env, timeout=120)


# -- finding Python --------------------------------------------------------------------------------

def test_the_fmu_runs_in_a_bare_native_host_with_python3_on_path(host, tiny, tmp_path):
    completed = run_host(host, tiny[2], tmp_path, ["--stop", "0.01"])
    assert completed.returncode == 0, completed.stderr
    assert (tmp_path / "out.csv").read_text().splitlines()[-1].startswith("0.01,0.01,")


@pytest.fixture(scope="module")
def python_without_numpy(tmp_path_factory) -> Path:
    venv = tmp_path_factory.mktemp("venv") / "bare"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python3"
    assert subprocess.run([str(python), "-c", "import numpy"], capture_output=True).returncode != 0
    return python


def fake_python(folder: Path, script: str) -> Path:
    path = folder / "python3"
    path.write_text(f"#!/bin/sh\n{script}\n")
    path.chmod(0o755)
    return path


@pytest.fixture(scope="module")
def hanging_python(tmp_path_factory) -> Path:
    return fake_python(tmp_path_factory.mktemp("hang"), "exec sleep 600")


@pytest.fixture(scope="module")
def silent_hanging_python(tmp_path_factory) -> Path:
    """One that closes its output at once, then does not exit."""
    return fake_python(tmp_path_factory.mktemp("silent"), "exec >&- 2>&-; exec sleep 600")


@pytest.mark.parametrize("case", ["missing", "without numpy", "hanging", "hanging, output closed", "none on PATH"])
def test_without_a_usable_python_instantiation_fails_with_what_to_set(case, host, tmp_path, python_without_numpy,
                                                                      hanging_python, silent_hanging_python):
    env, said = {
        "missing": ({"PIEZO_FMU_PYTHON": "/nonexistent/bin/python3"},
                    "tried PIEZO_FMU_PYTHON=/nonexistent/bin/python3: cannot run it (No such file or directory)"),
        "without numpy": ({"PIEZO_FMU_PYTHON": str(python_without_numpy)},
                          f"tried PIEZO_FMU_PYTHON={python_without_numpy}: it cannot import numpy "
                          "(ModuleNotFoundError(\"No module named 'numpy'\"))"),
        "hanging": ({"PIEZO_FMU_PYTHON": str(hanging_python), "PIEZO_FMU_PYTHON_TIMEOUT": "1"},
                    f"tried PIEZO_FMU_PYTHON={hanging_python}: it did not answer within 1 s"),
        "hanging, output closed": ({"PIEZO_FMU_PYTHON": str(silent_hanging_python), "PIEZO_FMU_PYTHON_TIMEOUT": "1"},
                                   f"tried PIEZO_FMU_PYTHON={silent_hanging_python}: it did not answer within 1 s"),
        "none on PATH": ({"PATH": str(tmp_path)}, f"there is no python3 on PATH={tmp_path}"),
    }[case]
    started = time.perf_counter()
    completed = run_host(host, FMU, tmp_path, ["--stop", "0.01"], env={**native.environment(), **env})
    assert time.perf_counter() - started < 30
    assert completed.returncode == 1  # an exit, not a signal
    assert completed.stdout == ""
    message, failure = completed.stderr.splitlines()
    assert message.startswith("[native_host] logStatusError (Error): piezo-fmu: no Python for this FMU: ")
    assert said in message and ADVICE in message
    assert failure == "native_host: fmi2Instantiate failed"


# -- statuses ---------------------------------------------------------------------------------------

REFUSALS = [  # --set, the call that refuses, the refusal's text
    ("gain=-1", "setting gain = -1", "gain = -1.0 is out of range; allowed range [0, inf)"),
    ("gain=inf", "setting gain = inf", "gain = inf is out of range; allowed range [0, inf)"),
    ("m=-1", "fmi{v}ExitInitializationMode", "invalid start values: m = -1.0 kg is out of range; allowed range (0, inf)"),
    ("t_max=0.0105", "fmi{v}DoStep", "the step to t = 0.011 s passes t_max = 0.0105 s, 105 % of 't_max'"),
]


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("start_value, call, text", REFUSALS)
def test_a_refused_call_returns_error_with_the_refusals_text_from_the_c_api(host, tiny, tmp_path, version,
                                                                            start_value, call, text):
    completed = run_host(host, tiny[version], tmp_path, ["--stop", "0.02", "--set", start_value])
    assert completed.returncode == 1
    assert f"(Error): {text}\n" in completed.stderr
    assert f"native_host: {call.format(v=version)} returned Error (3)" in completed.stderr
    assert "Fatal" not in completed.stderr
    out = tmp_path / "out.csv"  # written from the end of initialization on
    assert not out.exists() or "nan" not in out.read_text()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("start_value, call", [("gain=13", "setting gain = 13"), ("m=13", "fmi{v}ExitInitializationMode")])
def test_any_other_exception_stays_fatal(host, tiny, tmp_path, version, start_value, call):
    completed = run_host(host, tiny[version], tmp_path, ["--stop", "0.02", "--set", start_value])
    assert completed.returncode == 1
    assert "(Fatal): Fatal py exception encountered: " in completed.stderr  # pythonfmu's text, unchanged
    assert "RuntimeError('a plain failure, not a refusal')" in completed.stderr
    assert f"native_host: {call.format(v=version)} returned Fatal (4)" in completed.stderr


class Tiny:
    """A tiny FMU in fmpy (this process has Python: the loader leaves it as it is)."""

    def __init__(self, fmu: Path, folder: Path, logging_on: bool = True):
        self.md = read_model_description(str(fmu))
        self.version = int(self.md.fmiVersion[0])
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log: list[tuple[int, str]] = []
        kind = FMU2Slave if self.version == 2 else FMU3Slave
        self.fmu = kind(guid=self.md.guid, unzipDirectory=str(extract(fmu, folder)),
                        modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="tiny")
        if self.version == 2:  # a logger of its own, without fmpy's process-wide formatting proxy
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, category, message:
                                                           self._logged(status, message))
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self.fmu.instantiate(loggingOn=logging_on, callbacks=self.callbacks)
        else:
            self.fmu.instantiate(loggingOn=logging_on,
                                 logMessage=lambda env, status, category, message: self._logged(status, message))

    def _logged(self, status, message):
        self.log.append((int(status), message.decode()))

    def set(self, name: str, value: float) -> None:
        if self.version == 2:
            self.fmu.setReal([self.vr[name]], [value])
        else:
            self.fmu.setFloat64([self.vr[name]], [value])

    def get(self, name: str):
        if name in ("instances", "references"):
            getter = self.fmu.getInteger if self.version == 2 else self.fmu.getInt32
        else:
            getter = self.fmu.getReal if self.version == 2 else self.fmu.getFloat64
        return getter([self.vr[name]])[0]

    def initialize(self) -> None:
        if self.version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def step(self, t: float, h: float) -> None:
        self.fmu.doStep(t, h)

    def refused(self, call, *args) -> int:
        """The status of a call that must fail."""
        with pytest.raises(FMICallException) as failure:
            call(*args)
        return failure.value.status

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


@pytest.mark.parametrize("version", [2, 3])
def test_in_fmpy_each_refusal_is_an_error_and_reset_brings_the_instance_back(tiny, tmp_path, version):
    fmu = Tiny(tiny[version], tmp_path / "fmu")
    assert fmu.refused(fmu.set, "gain", -1.0) == ERROR
    assert fmu.log[-1] == (ERROR, "gain = -1.0 is out of range; allowed range [0, inf)")
    fmu.set("m", -1.0)
    assert fmu.refused(fmu.initialize) == ERROR
    assert fmu.log[-1] == (ERROR, "invalid start values: m = -1.0 kg is out of range; allowed range (0, inf)")
    fmu.fmu.reset()
    fmu.initialize()
    fmu.step(0.0, 0.5)
    assert fmu.refused(fmu.step, 0.5, -0.25) == ERROR
    assert fmu.log[-1] == (ERROR, "step size = -0.25 s is out of range; allowed range (0, inf)")
    fmu.fmu.reset()
    fmu.set("gain", 2.0)
    fmu.initialize()
    for k in range(4):
        fmu.step(0.25 * k, 0.25)
    assert fmu.get("y") == 2.0
    assert not any(status == FATAL for status, _ in fmu.log)
    fmu.close()


@pytest.mark.parametrize("version", [2, 3])
def test_in_fmpy_any_other_exception_stays_fatal(tiny, tmp_path, version):
    fmu = Tiny(tiny[version], tmp_path / "fmu")
    assert fmu.refused(fmu.set, "gain", 13.0) == FATAL
    assert fmu.log[-1][0] == FATAL and "RuntimeError('a plain failure, not a refusal')" in fmu.log[-1][1]
    fmu.fmu.freeInstance()


@pytest.mark.parametrize("version", [2, 3])
def test_an_instance_keeps_its_references_through_refusals_and_exceptions(tiny, tmp_path, version):
    """pythonfmu's exception handler released the slave, its class and its log queue at every
    exception while the instance kept using them (see ``piezo_fmu.build.archive.keep_references_on_exception``;
    shown below on the binary as shipped): three exceptions emptied the log queue's count, ten
    crashed the process. The project's slaves raise none (a refusal is logged), and the build mends
    the binary for what else might: 100 refusals and 100 exceptions, a garbage collection, a reset
    and a run, and the slave's reference count has not moved."""
    fmu = Tiny(tiny[version], tmp_path / "fmu")
    before = fmu.get("references")
    for _ in range(100):
        assert fmu.refused(fmu.set, "gain", -1.0) == ERROR
        assert fmu.refused(fmu.set, "gain", 13.0) == FATAL
    import gc

    gc.collect()
    assert fmu.get("references") == before
    fmu.fmu.reset()
    fmu.initialize()
    fmu.step(0.0, 0.5)
    assert fmu.get("y") == 0.5
    fmu.close()


def in_child(code: str, *args: str) -> str:
    """What ``code`` prints in a fresh Python with ``Tiny`` (for calls that may ruin a process)."""
    prelude = "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1]); from tests.test_loader import Tiny\n"
    completed = subprocess.run([sys.executable, "-c", prelude + code, str(REPO), *args], capture_output=True, text=True,
                               timeout=120)
    assert completed.returncode == 0, completed.stderr
    return completed.stdout.strip()


@pytest.mark.parametrize("version", [2, 3])
def test_pythonfmus_binary_as_shipped_drops_a_reference_at_every_exception(tmp_path, version):
    """Two exceptions take two references from the slave (and from its class and its log queue,
    which the process then frees too early: the child leaves at once)."""
    fmu = build_tiny(version, tmp_path / "build", mend_references=False)
    code = ("import os; fmu = Tiny(Path(sys.argv[2]), Path(sys.argv[3])); before = fmu.get('references')\n"
            "for _ in range(2): fmu.refused(fmu.set, 'gain', 13.0)\n"
            "print(before - fmu.get('references'), flush=True); os._exit(0)")
    assert in_child(code, str(fmu), str(tmp_path / "fmu")) == "2"


def test_the_mend_is_two_bytes_of_each_pythonfmu_binary_and_refuses_anything_else():
    for package, folder in (("pythonfmu", "linux64"), ("pythonfmu3", "x86_64-linux")):
        shipped = f"{package}/resources/binaries/{folder}/libpythonfmu-export.so"  # as installed, not as FMUs bundle it
        binary = Path(distribution(package).locate_file(shipped)).read_bytes()
        mended = fmu_archive.keep_references_on_exception(binary)
        changed = [i for i, (a, b) in enumerate(zip(binary, mended)) if a != b]
        assert len(mended) == len(binary) and len(changed) == 2 and mended[changed[0]:changed[0] + 2] == b"\xeb\x4c"
        with pytest.raises(ValueError, match="not a pythonfmu binary this mends"):
            fmu_archive.keep_references_on_exception(mended)


@pytest.mark.parametrize("version", [2, 3])
def test_information_needs_debug_logging_and_errors_do_not(tiny, tmp_path, version):
    quiet = Tiny(tiny[version], tmp_path / "quiet", logging_on=False)
    quiet.refused(quiet.set, "gain", -1.0)
    quiet.initialize()
    assert quiet.log == [(ERROR, "gain = -1.0 is out of range; allowed range [0, inf)")]
    quiet.close()

    chatty = Tiny(tiny[version], tmp_path / "chatty")
    chatty.initialize()
    assert chatty.log == [(OK, "start values checked")]
    chatty.fmu.reset()
    chatty.fmu.setDebugLogging(True, ["logStatusError"])  # not the message's category, logAll
    chatty.initialize()
    assert chatty.log == [(OK, "start values checked")]
    chatty.close()


def test_functions_the_fmu_lacks_answer_error_and_do_not_end_the_host(tiny, tmp_path):
    fmu = Tiny(tiny[2], tmp_path / "fmu")
    set_time = fmu.fmu.dll.fmi2SetTime  # pythonfmu has none
    set_time.argtypes, set_time.restype = [ctypes.c_void_p, ctypes.c_double], ctypes.c_int
    assert set_time(fmu.fmu.component, 0.0) == ERROR
    assert fmu.log[-1] == (ERROR, "fmi2SetTime is not supported by this FMU")
    fmu.fmu.freeInstance()
    # pythonfmu3 throws a C++ exception out of these (std::terminate): run where a failure cannot end pytest
    code = "fmu = Tiny(Path(sys.argv[2]), Path(sys.argv[3])); print(fmu.refused(fmu.fmu.getFloat32, [0]), fmu.log[-1][1])"
    assert in_child(code, str(tiny[3]), str(tmp_path / "fmu3")) == "3 fmi3GetFloat32 is not supported by this FMU"
    assert "fmi3GetFloat32" in pythonfmu3_unimplemented()


# -- one interpreter ---------------------------------------------------------------------------------

def test_fmi2_and_fmi3_fmus_in_one_native_process_share_one_interpreter(tiny, tmp_path):
    program = tmp_path / "two_fmus"
    subprocess.run([native.compiler(), "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-I", str(native.fmi_headers()),
                    str(REPO / "tests" / "two_fmus.c"), "-o", str(program), "-ldl"], check=True, capture_output=True)
    args = []
    for version in (2, 3):
        md = read_model_description(str(tiny[version]))
        vr = next(v.valueReference for v in md.modelVariables if v.name == "instances")
        args += [str(extract(tiny[version], tmp_path / f"fmi{version}")), IDENTIFIER[version], md.guid, str(vr)]
    completed = subprocess.run([str(program), *args], capture_output=True, text=True, env=native.environment(),
                               timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.split() == ["1", "2"]  # the FMI 3.0 slave is the interpreter's second


# -- the binary ------------------------------------------------------------------------------------

@pytest.mark.parametrize("version", [2, 3])
def test_the_loader_exports_the_whole_fmi_api_of_its_version(tmp_path, version):
    library = tmp_path / "loader.so"
    library.write_bytes(compile_loader(version))
    loaded = ctypes.CDLL(str(library))
    names = [function.name for function in api(version)]
    assert len(names) == (44 if version == 2 else 75)  # all the functions of the standard
    assert [name for name in names if not hasattr(loaded, name)] == []


@pytest.mark.parametrize("platform", PLATFORMS)
@pytest.mark.parametrize("version", [2, 3])
def test_the_loader_is_byte_reproducible(version, platform):
    assert compile_loader.__wrapped__(version, platform) == compile_loader.__wrapped__(version, platform)


def test_the_windows_loader_has_no_timestamp_and_imports_only_windows_own_dlls():
    """A PE file stamps its link time (the COFF header's TimeDateStamp) unless told not to."""
    import struct

    for version in (2, 3):
        binary = compile_loader(version, "windows")
        pe = struct.unpack_from("<I", binary, 0x3C)[0]
        assert binary[pe:pe + 4] == b"PE\0\0"
        assert struct.unpack_from("<I", binary, pe + 8)[0] == 0
        imported = {name.lower() for name in
                    (b"ADVAPI32.dll", b"KERNEL32.dll", b"msvcrt.dll", b"libgcc_s_seh-1.dll", b"libwinpthread-1.dll")
                    if name in binary}
        assert imported == {b"advapi32.dll", b"kernel32.dll", b"msvcrt.dll"}


@pytest.mark.parametrize("platform", PLATFORMS)
@pytest.mark.parametrize("version, fmu", [(2, FMU), (3, FMU.with_name("PiezoImpactDamper3.fmu"))])
def test_the_committed_fmus_have_the_loader_and_pythonfmus_binary_beside_it(version, fmu, platform):
    binary = f"{BINARIES[platform, version]}/{fmu.stem}"
    with zipfile.ZipFile(fmu) as archive:
        names = set(archive.namelist())
        loader = archive.read(f"{binary}{LIBRARY_SUFFIX[platform]}")
    assert f"{binary}{REAL_SUFFIXES[platform]}" in names
    assert loader == compile_loader(version, platform)
    assert not any(name.startswith("resources/piezo_fmu/build/loader") for name in names)
