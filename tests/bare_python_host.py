"""A Python host without numpy: an FMI 2.0 co-simulation FMU through ctypes and the standard
library alone, as a tool that embeds Python but not numpy would run it.

    python bare_python_host.py FMU_DIR STOP STEP

Runs the extracted FMU from 0 to STOP on the C host's grid (``hosts/native_host.c``: t_k = k *
step_ns / 1e9) and prints, as the C host writes its CSV rows (``%.17g``), the row of the last
time, then the file numpy was imported from inside the FMU. The FMU's messages go to stderr;
a failed call exits with status 1. ``tests/test_standalone.py`` runs it in virtual environments
that have no numpy.
"""

import ctypes
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

LOGGER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
ALLOCATE = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t)
FREE = ctypes.CFUNCTYPE(None, ctypes.c_void_p)


class Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOGGER), ("allocateMemory", ALLOCATE), ("freeMemory", FREE),
                ("stepFinished", ctypes.c_void_p), ("componentEnvironment", ctypes.c_void_p)]


def log(environment, name, status, category, message):
    print(f"[bare_python_host] {category.decode()} ({status}): {message.decode()}", file=sys.stderr)


def main(fmu_dir: str, stop: float, step: float) -> int:
    root = ET.parse(Path(fmu_dir) / "modelDescription.xml").getroot()
    identifier = root.find("CoSimulation").get("modelIdentifier")
    outputs = [(v.get("name"), int(v.get("valueReference")), v.find("Real") is not None)
               for v in root.iter("ScalarVariable") if v.get("causality") == "output"]
    fmu = ctypes.CDLL(str(Path(fmu_dir).absolute() / "binaries" / "linux64" / f"{identifier}.so"))
    libc = ctypes.CDLL(None)
    callbacks = Callbacks(LOGGER(log), ctypes.cast(libc.calloc, ALLOCATE), ctypes.cast(libc.free, FREE), None, None)
    fmu.fmi2Instantiate.restype = ctypes.c_void_p
    fmu.fmi2Instantiate.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                                    ctypes.POINTER(Callbacks), ctypes.c_int, ctypes.c_int]
    resources = (Path(fmu_dir).absolute() / "resources").as_uri().encode()
    component = fmu.fmi2Instantiate(b"bare", 1, root.get("guid").encode(), resources,
                                    ctypes.byref(callbacks), 0, 0)
    if not component:
        print("bare_python_host: fmi2Instantiate failed", file=sys.stderr)
        return 1
    c = ctypes.c_void_p(component)

    def call(name, *args):
        status = getattr(fmu, name)(c, *args)
        if status != 0:
            print(f"bare_python_host: {name} returned {status}", file=sys.stderr)
            raise SystemExit(1)

    fmu.fmi2SetupExperiment.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_double,
                                        ctypes.c_int, ctypes.c_double]
    fmu.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    call("fmi2SetupExperiment", 0, 0.0, 0.0, 1, stop)
    call("fmi2EnterInitializationMode")
    call("fmi2ExitInitializationMode")
    step_ns = round(step * 1e9)
    steps = round(stop * 1e9) // step_ns
    t = 0.0
    for k in range(steps):
        t_next = (k + 1) * step_ns / 1e9
        call("fmi2DoStep", t, t_next - t, 1)
        t = t_next
    row = [f"{t:.17g}"]
    for name, vr, real in outputs:
        value = (ctypes.c_double if real else ctypes.c_int)()
        call("fmi2GetReal" if real else "fmi2GetInteger", (ctypes.c_uint * 1)(vr), ctypes.c_size_t(1),
             ctypes.byref(value))
        row.append(f"{value.value:.17g}" if real else str(value.value))
    print(",".join(row))
    print(sys.modules["numpy"].__file__)
    call("fmi2Terminate")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], float(sys.argv[2]), float(sys.argv[3])))
