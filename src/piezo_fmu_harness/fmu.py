"""The FMU as the harness sees it: where it is, what its modelDescription declares, and one
reusable co-simulation instance driven through fmpy.

The harness knows the piezo-impact damper only through ``PiezoImpactDamper.fmu``: names,
types, units and bounds of the parameters come from its modelDescription, and every run goes
through :mod:`fmpy`. Nothing here imports the simulation core.
"""

from __future__ import annotations

import atexit
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from . import fmus

#: Environment variable that points the harness at another FMU file.
FMU_ENV = "PIEZO_FMU"

#: The FMU's end-of-run outputs that make a point's metrics, under the names the harness uses
#: (the paper's symbols where it has one). Units are SI: DI in m/s, voltages in V, power in W,
#: energies in J.
METRIC_OUTPUTS = {
    "impact_count": "impact_count",
    "DI": "damping_inclination",
    "V_rms": "voltage_rms",
    "P_ave": "average_power",
    "last_impact_voltage": "last_impact_voltage",
    "energy_dissipated": "energy_dissipated",
    "energy_balance_error": "energy_balance_error",
}
METRIC_UNITS = {
    "impact_count": "1", "DI": "m/s", "V_rms": "V", "P_ave": "W", "last_impact_voltage": "V",
    "energy_dissipated": "J", "energy_balance_error": "J", "DI_ls": "m/s",
}
#: End-of-run outputs (J) a point's record also carries when the FMU declares them: the energy
#: harvested in the loads (voltage_model 1 and 2), in total and per barrier.
ENERGY_OUTPUTS = ("harvested_energy", "harvested_energy_left", "harvested_energy_right")
#: Metrics a point's record also carries when the FMU declares them (older FMUs lack them), under the
#: harness's names: the robust damping inclination DI_ls (m/s).
OPTIONAL_METRICS = {"DI_ls": "damping_inclination_ls"}


class FmuRunError(RuntimeError):
    """The FMU rejected a run (a bad combination of parameters, a failed step)."""


def default_fmu_path() -> Path:
    """The FMU to use when none is given: ``$PIEZO_FMU`` when it is set, else the FMI 2.0 FMU
    installed with the package (:func:`piezo_fmu_harness.fmus.path`)."""
    if os.environ.get(FMU_ENV):
        return Path(os.environ[FMU_ENV])
    return fmus.path(fmi_version=2)


#: The least positive double: the ``min`` that declares a range open at 0 (FMI has no exclusive
#: bounds; see :mod:`piezo_fmu.fmi.variables`).
OPEN_AT_ZERO = math.nextafter(0.0, math.inf)


@dataclass(frozen=True)
class Parameter:
    """One FMU parameter as its modelDescription declares it (SI units)."""

    name: str
    type: str  # "Real" or "Integer"
    value_reference: int
    start: float
    min: Optional[float]
    max: Optional[float]
    unit: Optional[str]
    description: str

    def bounds_text(self) -> str:
        open_at_zero = self.min == OPEN_AT_ZERO
        lo = "-inf" if self.min is None else "0" if open_at_zero else f"{self.min:g}"
        hi = "inf" if self.max is None else f"{self.max:g}"
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if open_at_zero else '['}{lo}, {hi}]{unit}"

    def coerce(self, value) -> float | int:
        """``value`` as this parameter's type, within the modelDescription's min and max.

        Raises ``ValueError`` naming the parameter, the value and the allowed range.
        """
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{self.name} = {value!r} is not a number") from None
        if not math.isfinite(number):
            raise ValueError(f"{self.name} = {value!r} is not finite")
        if self.type == "Integer":
            if number != round(number):
                raise ValueError(f"{self.name} = {value!r} is not an integer ({self.name} is an Integer parameter)")
            number = int(round(number))
        if self.min is not None and number < self.min:
            below = "is not above 0" if self.min == OPEN_AT_ZERO else f"is below its minimum {self.min:g}"
            raise ValueError(f"{self.name} = {value!r} {below}; "
                             f"allowed range {self.bounds_text()} (from the FMU's modelDescription)")
        if self.max is not None and number > self.max:
            raise ValueError(f"{self.name} = {value!r} is above its maximum {self.max:g}; "
                             f"allowed range {self.bounds_text()} (from the FMU's modelDescription)")
        return number


class FmuModel:
    """The FMU file and its modelDescription: parameters, calculated parameters, outputs, GUID."""

    def __init__(self, path: Path | str):
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(
                f"FMU not found at {self.path}; build it with `python -m piezo_fmu.build` "
                f"or point --fmu (or ${FMU_ENV}) at it")
        self.model_description = read_model_description(str(self.path), validate=False)
        self.guid = self.model_description.guid
        self.model_identifier = self.model_description.coSimulation.modelIdentifier
        self.parameters: dict[str, Parameter] = {}
        self.outputs: dict[str, tuple[str, int]] = {}
        #: Inputs (Real), by name: their value references.
        self.inputs: dict[str, int] = {}
        #: Calculated parameters (fixed after initialization), as ``(type, valueReference)``.
        self.calculated: dict[str, tuple[str, int]] = {}
        #: The unit of every variable (None for a number without one), by name.
        self.units: dict[str, Optional[str]] = {}
        for variable in self.model_description.modelVariables:
            self.units[variable.name] = variable.unit or (variable.declaredType.unit if variable.declaredType else None)
            if variable.causality == "parameter":
                self.parameters[variable.name] = Parameter(
                    name=variable.name, type=variable.type, value_reference=variable.valueReference,
                    start=_number(variable.start, variable.type), min=_optional(variable.min),
                    max=_optional(variable.max), unit=variable.unit,
                    description=variable.description or "")
            elif variable.causality == "output":
                self.outputs[variable.name] = (variable.type, variable.valueReference)
            elif variable.causality == "input":
                self.inputs[variable.name] = variable.valueReference
            elif variable.causality == "calculatedParameter":
                self.calculated[variable.name] = (variable.type, variable.valueReference)
        missing = [name for name in METRIC_OUTPUTS.values() if name not in self.outputs]
        if missing:
            raise ValueError(f"{self.path} lacks the outputs {missing}; is it the piezo-impact damper FMU?")

    def defaults(self) -> dict[str, float | int]:
        """Every parameter's start value (the nominal case), by name."""
        return {name: p.start for name, p in self.parameters.items()}

    def extract(self) -> str:
        """Unzip the FMU into a fresh temporary folder and return its path."""
        return extract(str(self.path))


def discard(folder: str) -> None:
    """Remove an FMU's extraction folder, unless this process's ``piezo_fmu`` was imported from it:
    the first FMU a process loads gives the process its copy of the package, and a module of it
    imported later (the batch engine of the studies of many starts) needs its files. Such a folder
    is removed when the process exits."""
    home = getattr(sys.modules.get("piezo_fmu"), "__file__", None)
    if home and Path(folder).resolve() in Path(home).resolve().parents:
        atexit.register(shutil.rmtree, folder, True)
        return
    shutil.rmtree(folder, ignore_errors=True)


def _optional(text) -> Optional[float]:
    return None if text is None else float(text)


def _number(text, kind: str) -> float | int:
    if text is None:
        return 0
    return int(text) if kind == "Integer" else float(text)


class Instance:
    """One instantiated co-simulation FMU, reused for many runs (reset between them).

    Parameters
    ----------
    model : FmuModel
        The FMU's description.
    unzipdir : str
        Folder the FMU was extracted to (:meth:`FmuModel.extract`); may be shared by processes.
    """

    def __init__(self, model: FmuModel, unzipdir: str, instance_name: str = "harness"):
        self.model = model
        self.unzipdir = unzipdir
        self.messages: list[str] = []
        self._callbacks = fmi2CallbackFunctions()
        # The ctypes callbacks must outlive the instance: keep them on self.
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu = FMU2Slave(guid=model.guid, unzipDirectory=unzipdir,
                             modelIdentifier=model.model_identifier, instanceName=instance_name)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self._fresh = True
        outputs = {**METRIC_OUTPUTS, **{key: name for key, name in OPTIONAL_METRICS.items() if name in model.outputs},
                   **{name: name for name in ENERGY_OUTPUTS if name in model.outputs}}
        self._metric_refs = {
            kind: [(key, self.model.outputs[name][1]) for key, name in outputs.items()
                   if self.model.outputs[name][0] == kind]
            for kind in ("Real", "Integer")
        }
        self._metric_keys = list(outputs)

    def _log(self, component, instance_name, status, category, message) -> None:
        self.messages.append(message.decode("utf-8", "replace"))

    def renew(self) -> None:
        """Make the instance ready for a new run: reset it unless it is fresh."""
        if not self._fresh:
            self.fmu.reset()
        self._fresh = False
        self.messages.clear()

    def start(self, values: dict, inputs: Optional[dict] = None) -> None:
        """Reset the instance (unless fresh), set ``values`` (SI) and the ``inputs`` at t = 0
        (by name; the FMU takes them as the initial state of the base), and initialize at t = 0."""
        self.renew()
        if inputs:
            self.fmu.setReal([self.model.inputs[name] for name in inputs], [float(v) for v in inputs.values()])
        reals, integers = ([], []), ([], [])
        for name, value in values.items():
            parameter = self.model.parameters[name]
            target = integers if parameter.type == "Integer" else reals
            target[0].append(parameter.value_reference)
            target[1].append(int(value) if parameter.type == "Integer" else float(value))
        if reals[0]:
            self.fmu.setReal(*reals)
        if integers[0]:
            self.fmu.setInteger(*integers)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def metrics(self) -> dict:
        """The metric outputs now, under the harness's names (see :data:`METRIC_OUTPUTS`), and
        the :data:`OPTIONAL_METRICS` and :data:`ENERGY_OUTPUTS` the FMU declares."""
        result = {}
        for kind, getter in (("Real", self.fmu.getReal), ("Integer", self.fmu.getInteger)):
            refs = self._metric_refs[kind]
            if refs:
                for (key, _), value in zip(refs, getter([vr for _, vr in refs])):
                    result[key] = value
        return {key: result[key] for key in self._metric_keys}

    def read(self, names) -> dict:
        """The current values of outputs or calculated parameters ``names`` (after
        :meth:`start`), by name. Raises ``KeyError`` for a name the FMU does not declare."""
        by_kind: dict[str, list[tuple[str, int]]] = {"Real": [], "Integer": []}
        for name in names:
            kind, vr = self.model.outputs.get(name) or self.model.calculated[name]
            by_kind["Integer" if kind == "Integer" else "Real"].append((name, vr))
        result = {}
        for kind, getter in (("Real", self.fmu.getReal), ("Integer", self.fmu.getInteger)):
            if by_kind[kind]:
                result.update(zip((n for n, _ in by_kind[kind]), getter([vr for _, vr in by_kind[kind]])))
        return {name: result[name] for name in names}

    def failure(self, error: Exception) -> FmuRunError:
        """An :class:`FmuRunError` carrying the FMU's own messages about ``error``."""
        return FmuRunError("; ".join(dict.fromkeys(self.messages)) or str(error))

    def run(self, values: dict, stop_time: float, step: float) -> dict:
        """Simulate from 0 to ``stop_time`` (s) with communication step ``step`` (s).

        Returns the end-of-run metrics (:meth:`metrics`). Raises :class:`FmuRunError` with the
        FMU's own message if it rejects the parameters or a step.
        """
        n_steps = max(1, math.ceil(stop_time / step - 1e-9))
        try:
            self.start(values)
            do_step = self.fmu.doStep
            t = 0.0
            for k in range(1, n_steps + 1):
                t_next = stop_time if k == n_steps else k * step
                do_step(currentCommunicationPoint=t, communicationStepSize=t_next - t)
                t = t_next
            return self.metrics()
        except FMICallException as error:
            raise self.failure(error) from None

    def run_point(self, index: int, values: dict, stop_time: float, step: float) -> dict:
        """One sweep point as a JSON-safe record: its index and values, status, metrics, and its
        cost: ``seconds`` (wall) and ``cpu_seconds`` (this process's CPU time)."""
        begin, begin_cpu = time.perf_counter(), time.process_time()
        record = {"index": index, "values": values}
        try:
            metrics = self.run(values, stop_time, step)
            # JSON has no NaN: a metric the FMU leaves undefined is recorded as null.
            record.update(status="ok", error=None,
                          **{k: (v if math.isfinite(v) else None) for k, v in metrics.items()})
        except FmuRunError as error:
            record.update(status="error", error=str(error), **{key: None for key in self._metric_keys})
        record["seconds"] = time.perf_counter() - begin
        record["cpu_seconds"] = time.process_time() - begin_cpu
        return record

    def free(self) -> None:
        """Release the instance (the library stays loaded, as fmpy does)."""
        try:
            self.fmu.freeInstance()
        except Exception:  # noqa: BLE001 - best effort at teardown
            pass
