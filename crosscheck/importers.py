"""The FMU driven by each importer over the cross-check scenario.

Every driver runs the same protocol: set the start values and the inputs of ``t_0``, initialize,
record the outputs at ``t_0``; then for each step ``k`` set the inputs of row ``k`` of the input
table, step from ``t_k``, record the outputs. They differ only in who computes the
communication points:

- ``fmpy``: the project's master loop on fmpy's FMI 2.0 wrapper (``fmpy.fmi2.FMU2Slave``), on
  the nanosecond grid of :func:`crosscheck.scenario.grid` (or on any grid given to it);
- ``fmpy-simulate``: fmpy's own ``simulate_fmu`` with the input table as its ``input``. It
  computes ``t_k = start + k * step`` and interpolates the inputs linearly at those times;
- ``libcosim``: OSP libcosim through ``libcosimpy``, fixed-step execution; time is an integer
  count of nanoseconds, converted to seconds for ``fmi2DoStep`` (libcosim's
  ``to_double_time_point``: ``t_k = (k * 10**6) / 1e9``; step ``t_{k+1} - t_k``). The inputs
  are set by an override manipulator before each step;
- ``ecos``: ecos through ``ecospy``; it adds the step to its time at every step
  (``t_{k+1} = t_k + 0.001`` in floating point) and passes ``(t_k, 0.001)`` to ``fmi2DoStep``.
  The inputs are set through ``set_real`` before each step;
- ``native``: the project's C host (``hosts/native_host.c``) in a bare environment (its PATH
  holding this Python; the FMU's loader finds it);
- ``fmpy-fmi3``, ``ecos-fmi3`` and ``native-fmi3``: the same masters as ``fmpy``, ``ecos`` and
  ``native`` on the FMI 3.0 FMU (``fmus/PiezoImpactDamper3.fmu``, co-simulation; fmpy's
  ``FMU3Slave``).

Each returns a :class:`Result` with the output time series and, where the driver knows them,
the ``(t_k, h_k)`` it passed to ``fmi2DoStep``.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from crosscheck import scenario

IMPORTERS = ("fmpy", "libcosim", "ecos", "native", "fmpy-simulate", "fmpy-fmi3", "ecos-fmi3", "native-fmi3")
#: FMI 3.0 type names as the FMI 2.0 ones the results use.
_FMI2_TYPE = {"Float64": "Real", "Int32": "Integer"}


@dataclass
class Result:
    importer: str
    time: np.ndarray
    outputs: dict[str, np.ndarray]
    #: ``(currentCommunicationPoint, communicationStepSize)`` of every fmi2DoStep, when known.
    steps: list[tuple[float, float]] = field(default_factory=list)


def output_variables(fmu: Path) -> list[tuple[str, int, str]]:
    """``(name, valueReference, type)`` of every output, in model order."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return [(v.name, v.valueReference, _FMI2_TYPE.get(v.type, v.type)) for v in md.modelVariables
            if v.causality == "output"]


def _value_references(fmu: Path) -> dict[str, tuple[int, str]]:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return {v.name: (v.valueReference, _FMI2_TYPE.get(v.type, v.type)) for v in md.modelVariables}


def _check_input_grid(in_time: np.ndarray, times: np.ndarray) -> None:
    """The input table must hold one row per communication point (the scenario's does)."""
    if len(in_time) < len(times) or np.any(
            np.abs(in_time[:len(times)] - times) > scenario.TIME_RTOL * np.maximum(1.0, np.abs(times))):
        raise ValueError("the input table is not sampled on the communication grid")


def _finish(importer: str, times: Sequence[float], rows: list[list], outs: list[tuple[str, int, str]],
            steps: list[tuple[float, float]]) -> Result:
    columns = {}
    for j, (name, _, kind) in enumerate(outs):
        values = [row[j] for row in rows]
        columns[name] = np.array(values, dtype=np.int64 if kind == "Integer" else float)
    return Result(importer, np.asarray(times, dtype=float), columns, steps)


# -- fmpy -----------------------------------------------------------------------------------------

def run_fmpy(fmu: Path = scenario.FMU_PATH, times: Optional[np.ndarray] = None,
             inputs: Optional[dict[str, np.ndarray]] = None, start_values: Optional[dict] = None,
             steps: Optional[Sequence[tuple[float, float]]] = None, importer: str = "fmpy") -> Result:
    """fmpy's FMI 2.0 wrapper under the project's master loop.

    The communication points are ``times`` (default: the scenario's grid), the step passed to
    ``fmi2DoStep`` being ``t_{k+1} - t_k``; or, with ``steps``, exactly the given
    ``(currentCommunicationPoint, communicationStepSize)`` pairs (to replay another master's
    calls). ``inputs`` (default: the scenario's input table) gives the input values of each
    step by row; ``{}`` sets no input. ``start_values`` default to the scenario's.
    """
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    if steps is not None:
        steps = [(float(t), float(h)) for t, h in steps]
        times = np.array([steps[0][0]] + [t + h for t, h in steps])
    times = scenario.grid() if times is None else np.asarray(times, dtype=float)
    if steps is None:
        steps = [(float(times[k]), float(times[k + 1] - times[k])) for k in range(len(times) - 1)]
    if inputs is None:
        in_time, inputs = scenario.read_inputs()
        _check_input_grid(in_time, scenario.grid())
    start_values = dict(scenario.START_VALUES if start_values is None else start_values)
    md = read_model_description(str(fmu))
    refs = _value_references(fmu)
    fmi3 = md.fmiVersion.startswith("3")
    outs = output_variables(fmu)
    real_outs = [vr for _, vr, kind in outs if kind == "Real"]
    int_outs = [vr for _, vr, kind in outs if kind == "Integer"]
    order = _positions(outs)
    input_names = list(inputs)
    input_vrs = [refs[name][0] for name in input_names]

    unzipdir = extract(str(fmu))
    slave = (FMU3Slave if fmi3 else FMU2Slave)(guid=md.guid, unzipDirectory=unzipdir,
                                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName="damper")
    get_real, get_integer, set_real, set_integer = (
        (slave.getFloat64, slave.getInt32, slave.setFloat64, slave.setInt32) if fmi3
        else (slave.getReal, slave.getInteger, slave.setReal, slave.setInteger))
    rows = []
    try:
        slave.instantiate()
        if not fmi3:
            slave.setupExperiment(startTime=float(times[0]), stopTime=float(times[-1]))
        for name, value in start_values.items():
            vr, kind = refs[name]
            if kind == "Integer":
                set_integer([vr], [int(value)])
            else:
                set_real([vr], [float(value)])

        def set_inputs(k: int) -> None:
            if input_vrs:
                set_real(input_vrs, [float(inputs[name][k]) for name in input_names])

        def read() -> list:
            reals = get_real(real_outs)
            ints = get_integer(int_outs) if int_outs else []
            return [reals[i] if kind == "Real" else ints[i] for kind, i in order]

        set_inputs(0)
        if fmi3:
            slave.enterInitializationMode(startTime=float(times[0]), stopTime=float(times[-1]))
        else:
            slave.enterInitializationMode()
        slave.exitInitializationMode()
        rows.append(read())
        for k, (t, h) in enumerate(steps):
            set_inputs(k)
            slave.doStep(t, h)
            rows.append(read())
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzipdir, ignore_errors=True)
    return _finish(importer, times, rows, outs, steps)


def _positions(outs: list[tuple[str, int, str]]) -> list[tuple[str, int]]:
    """For each output, its type and its index within the getReal / getInteger call."""
    counts = {"Real": 0, "Integer": 0}
    positions = []
    for _, _, kind in outs:
        positions.append((kind, counts[kind]))
        counts[kind] += 1
    return positions


def run_fmpy_simulate(fmu: Path = scenario.FMU_PATH) -> Result:
    """fmpy's own ``simulate_fmu`` (its own time arithmetic and input interpolation)."""
    from fmpy import simulate_fmu
    from fmpy.util import read_csv

    outs = output_variables(fmu)
    signals = read_csv(str(scenario.IN_CSV))
    result = simulate_fmu(str(fmu), start_time=scenario.START_TIME, stop_time=scenario.STOP_TIME,
                          output_interval=scenario.STEP_SIZE, start_values=dict(scenario.START_VALUES),
                          input=signals, output=[name for name, _, _ in outs])
    columns = {name: np.asarray(result[name], dtype=np.int64 if kind == "Integer" else float)
               for name, _, kind in outs}
    times = scenario.multiplied_grid()
    steps = [(float(times[k]), float(times[k + 1] - times[k])) for k in range(len(times) - 1)]
    return Result("fmpy-simulate", np.asarray(result["time"], dtype=float), columns, steps)


# -- OSP libcosim ---------------------------------------------------------------------------------

def quiet_libcosim() -> None:
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.WARNING)


def run_libcosim(fmu: Path = scenario.FMU_PATH) -> Result:
    """OSP libcosim (``libcosimpy``): fixed-step execution at the scenario's step."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimSlave import CosimLocalSlave

    quiet_libcosim()
    in_time, inputs = scenario.read_inputs()
    _check_input_grid(in_time, scenario.grid())
    refs = _value_references(fmu)
    outs = output_variables(fmu)
    n = len(scenario.grid()) - 1

    execution = CosimExecution.from_step_size(step_size=scenario.step_ns())
    index = execution.add_local_slave(CosimLocalSlave(fmu_path=str(fmu), instance_name="damper"))
    if index < 0:
        raise RuntimeError("libcosim could not load the FMU")
    for name, value in scenario.START_VALUES.items():
        execution.real_initial_value(index, refs[name][0], float(value))
    for name in inputs:
        execution.real_initial_value(index, refs[name][0], float(inputs[name][0]))
    manipulator = CosimManipulator.create_override()
    execution.add_manipulator(manipulator)
    recorder = TimeSeries(execution, {index: outs}, n + 1)
    input_vrs = [refs[name][0] for name in inputs]
    for k in range(n):
        manipulator.slave_real_values(index, input_vrs, [float(inputs[name][k]) for name in inputs])
        if not execution.step(1):
            raise RuntimeError(f"libcosim failed at step {k}: {execution.status()}")
    times_ns, columns = recorder.samples(index, n + 1)
    if times_ns != [k * scenario.step_ns() for k in range(n + 1)]:
        raise RuntimeError("libcosim recorded an unexpected time grid")
    steps = [(times_ns[k] / 1e9, times_ns[k + 1] / 1e9 - times_ns[k] / 1e9) for k in range(n)]
    return Result("libcosim", np.array(times_ns) / 1e9, columns, steps)


class TimeSeries:
    """A libcosim time-series observer over given outputs (``samples`` per variable, the initial
    values included).

    ``libcosimpy``'s sample reader drops samples of step 0, so the C function is called directly.
    """

    def __init__(self, execution, variables: dict[int, list[tuple[str, int, str]]], samples: int):
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimObserver import CosimObserver

        # The unbuffered observer keeps only the latest 10 000 samples.
        self.observer = CosimObserver.create_time_series(buffer_size=samples)
        execution.add_observer(self.observer)
        self.variables = variables
        for index, outs in variables.items():
            for _, vr, kind in outs:
                var_type = CosimVariableType.INTEGER if kind == "Integer" else CosimVariableType.REAL
                if not self.observer.start_time_series(index, vr, var_type):
                    raise RuntimeError(f"libcosim cannot observe variable {vr} of slave {index}")

    def samples(self, index: int, count: int) -> tuple[list[int], dict[str, np.ndarray]]:
        """``(times in ns, {name: values})`` of the first ``count`` samples of slave ``index``."""
        from ctypes import POINTER, c_double, c_int, c_int64, c_size_t, c_uint32

        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy._internal import libcosimc, wrap_function

        columns, times = {}, None
        for name, vr, kind in self.variables[index]:
            c_type = c_int if kind == "Integer" else c_double
            fetch = wrap_function(
                lib=libcosimc(),
                funcname="cosim_observer_slave_get_integer_samples" if kind == "Integer"
                else "cosim_observer_slave_get_real_samples",
                argtypes=[POINTER(CosimObserver), c_int, c_uint32, c_int64, c_size_t, POINTER(c_type),
                          POINTER(c_int64), POINTER(c_int64)],
                restype=c_int64)
            values, steps, points = (c_type * count)(), (c_int64 * count)(), (c_int64 * count)()
            got = fetch(self.observer.ptr(), index, vr, 0, count, values, steps, points)
            if got != count or list(steps) != list(range(count)):
                raise RuntimeError(f"libcosim returned {got} samples of {name}, {count} expected")
            columns[name] = np.array(values[:], dtype=np.int64 if kind == "Integer" else float)
            times = list(points) if times is None else times
            if list(points) != times:
                raise RuntimeError("libcosim samples of one slave are on different time points")
        return times, columns


# -- ecos -----------------------------------------------------------------------------------------

def run_ecos(fmu: Path = scenario.FMU_PATH, importer: str = "ecos") -> Result:
    """ecos (``ecospy``): fixed-step simulation at the scenario's step."""
    from ecospy import EcosLib, EcosSimulation, EcosSimulationStructure

    EcosLib.set_log_level("warn")
    in_time, inputs = scenario.read_inputs()
    _check_input_grid(in_time, scenario.grid())
    outs = output_variables(fmu)
    n = len(scenario.grid()) - 1

    structure = EcosSimulationStructure()
    structure.add_model("damper", str(fmu))
    initial = {f"damper::{name}": float(value) for name, value in scenario.START_VALUES.items()}
    initial.update({f"damper::{name}": float(inputs[name][0]) for name in inputs})
    structure.add_parameter_set("initial", initial)
    simulation = EcosSimulation(structure=structure, step_size=scenario.STEP_SIZE)
    try:
        if not simulation.init(start_time=scenario.START_TIME, parameter_set="initial"):
            raise RuntimeError(f"ecos could not initialize: {EcosLib.get_last_error()}")

        def read() -> list:
            return [simulation.get_integer(f"damper::{name}") if kind == "Integer"
                    else simulation.get_real(f"damper::{name}") for name, _, kind in outs]

        rows, times, steps = [read()], [simulation.get_time()], []
        for k in range(n):
            for name in inputs:
                simulation.set_real(f"damper::{name}", float(inputs[name][k]))
            t = simulation.get_time()
            simulation.step(1)
            steps.append((t, scenario.STEP_SIZE))
            times.append(simulation.get_time())
            rows.append(read())
        simulation.terminate()
    finally:
        simulation.free()
        structure.free()
    return _finish(importer, times, rows, outs, steps)


# -- the C host -----------------------------------------------------------------------------------

def run_native(fmu: Path = scenario.FMU_PATH, importer: str = "native") -> Result:
    """The project's C host, in a bare environment, on the cross-check input."""
    from hosts import native

    with tempfile.TemporaryDirectory(prefix="piezo_native_") as scratch:
        out = Path(scratch) / "out.csv"
        args = ["--start", repr(scenario.START_TIME), "--stop", repr(scenario.STOP_TIME),
                "--step", repr(scenario.STEP_SIZE), "--in", str(scenario.IN_CSV)]
        for name, value in scenario.START_VALUES.items():
            args += ["--set", f"{name}={value!r}"]
        native.run(fmu, out, args)
        time, outputs = scenario.read_csv(out)
    kinds = {name: kind for name, _, kind in output_variables(fmu)}
    outputs = {name: values.astype(np.int64 if kinds[name] == "Integer" else float)
               for name, values in outputs.items()}
    times = scenario.grid()
    steps = [(float(times[k]), float(times[k + 1] - times[k])) for k in range(len(times) - 1)]
    return Result(importer, time, outputs, steps)


RUNNERS: dict[str, Callable[..., Result]] = {
    "fmpy": run_fmpy,
    "fmpy-simulate": run_fmpy_simulate,
    "libcosim": run_libcosim,
    "ecos": run_ecos,
    "native": run_native,
    "fmpy-fmi3": lambda fmu=scenario.FMU3_PATH: run_fmpy(fmu, importer="fmpy-fmi3"),
    "ecos-fmi3": lambda fmu=scenario.FMU3_PATH: run_ecos(fmu, importer="ecos-fmi3"),
    "native-fmi3": lambda fmu=scenario.FMU3_PATH: run_native(fmu, importer="native-fmi3"),
}
#: The FMU each importer runs by default.
DEFAULT_FMUS = {importer: scenario.FMU3_PATH if importer.endswith("-fmi3") else scenario.FMU_PATH
                for importer in IMPORTERS}


def run(importer: str, fmu: Optional[Path] = None) -> Result:
    if importer not in RUNNERS:
        raise ValueError(f"unknown importer {importer!r}; known: {', '.join(RUNNERS)}")
    return RUNNERS[importer](DEFAULT_FMUS[importer] if fmu is None else fmu)
