"""The FMI 3.0 FMU as a co-simulation: the FMI 2.0 FMU's bits, its state, its errors.

- FMI 3.0 co-simulation equals FMI 2.0 co-simulation bit for bit at every communication point,
  every output: the nominal case, a harmonic base, and the nominal damper under circuit model 1.
- The full state is saved and restored (get/set and serialize/deserialize): a rerun from it gives
  the same bits.
- A run that starts at t0 != 0 (pythonfmu3 passes FMI 3.0's start time on only with the first
  step) gives the bits of a run from 0 shifted by t0.
- Bad values: the same clear messages as FMI 2.0; a refused step returns fmi3Error; a wrong access
  is logged, never raised (an exception through pythonfmu3's binary damages the instance and can
  crash the process at the next garbage collection); the instance recovers after fmi3Reset.
"""

from __future__ import annotations

import gc
import math
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave, fmi3Error

ROOT = Path(__file__).resolve().parents[1]
FMU2 = ROOT / "fmus" / "PiezoImpactDamper.fmu"
FMU3 = ROOT / "fmus" / "PiezoImpactDamper3.fmu"


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """(model description, unzip folder) of each FMU, by FMI version."""
    return {version: (read_model_description(str(path)), extract(str(path), unzipdir=str(tmp_path_factory.mktemp(f"fmi{version}"))))
            for version, path in ((2, FMU2), (3, FMU3))}


class Host:
    """One initialized co-simulation instance of either FMI version, its log collected."""

    def __init__(self, fmus, version: int, start_values: dict | None = None, start_time: float = 0.0):
        md, unzipdir = fmus[version]
        self.version, self.log = version, []
        self.variables = {v.name: v for v in md.modelVariables}
        kwargs = dict(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=f"fmi{version}")
        if version == 2:
            self.fmu = FMU2Slave(**kwargs)
            self.fmu.instantiate(loggingOn=True)
            self.fmu.setupExperiment(startTime=start_time)
            self.fmu.enterInitializationMode()
        else:
            self.fmu = FMU3Slave(**kwargs)
            self.fmu.instantiate(loggingOn=True, logMessage=self._log)
            self.fmu.enterInitializationMode(startTime=start_time)
        self.set(**(start_values or {}))
        self.fmu.exitInitializationMode()
        self.outputs_real = [v for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")]
        self.outputs_int = [v for v in md.modelVariables if v.causality == "output" and v.type in ("Integer", "Int32")]

    def _log(self, env, status, category, message):
        self.log.append((status, message.decode("utf-8")))

    def errors(self) -> list[str]:
        return [message for status, message in self.log if status >= fmi3Error]

    def set(self, **values) -> None:
        for name, value in values.items():
            v = self.variables[name]
            integer = v.type in ("Integer", "Int32")
            if self.version == 2:
                (self.fmu.setInteger if integer else self.fmu.setReal)([v.valueReference], [value])
            else:
                (self.fmu.setInt32 if integer else self.fmu.setFloat64)([v.valueReference], [value])

    def outputs(self) -> dict:
        get_real, get_int = ((self.fmu.getReal, self.fmu.getInteger) if self.version == 2
                             else (self.fmu.getFloat64, self.fmu.getInt32))
        values = dict(zip((v.name for v in self.outputs_real), get_real([v.valueReference for v in self.outputs_real])))
        values.update(zip((v.name for v in self.outputs_int), get_int([v.valueReference for v in self.outputs_int])))
        return values

    def step(self, t: float, h: float) -> None:
        self.fmu.doStep(t, h)

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def harmonic(t: float) -> dict:
    Y, w = 1e-3, 31.6
    return {"base_displacement": Y * math.sin(w * t), "base_velocity": Y * w * math.cos(w * t)}


CASES = {
    "nominal": ({}, None),
    "harmonic base": ({"p0": 0.0, "q0": 0.0}, harmonic),
    "circuit model 1": ({"voltage_model": 1, "R_load": 3.6e6}, None),
}


@pytest.mark.parametrize("case", CASES)
def test_fmi3_co_simulation_equals_fmi2_bit_for_bit_at_every_communication_point(fmus, case):
    start_values, base = CASES[case]
    hosts = [Host(fmus, version, start_values) for version in (2, 3)]
    h, n = 1e-3, 2000
    impacts = 0
    for k in range(n):
        t = k * h
        rows = []
        for host in hosts:
            if base is not None:
                host.set(**base(t))
            host.step(t, (k + 1) * h - t)
            rows.append(host.outputs())
        assert rows[0] == rows[1], (case, t)  # every output, bit for bit (NaN would fail: there is none)
        impacts = rows[0]["impact_count"]
    assert impacts > 10
    for host in hosts:
        host.close()


def test_the_full_state_is_saved_and_restored_bit_for_bit(fmus):
    host = Host(fmus, 3, {"voltage_model": 1})
    h = 1e-3
    for k in range(500):
        host.step(k * h, h)
    state = host.fmu.getFMUState()
    serialized = host.fmu.serializeFMUState(state)
    first = []
    for k in range(500, 1000):
        host.step(k * h, h)
        first.append(host.outputs())
    host.fmu.setFMUState(state)
    again = []
    for k in range(500, 1000):
        host.step(k * h, h)
        again.append(host.outputs())
    host.fmu.setFMUState(host.fmu.deserializeFMUState(serialized))
    restored = []
    for k in range(500, 1000):
        host.step(k * h, h)
        restored.append(host.outputs())
    assert first == again == restored and first[-1]["impact_count"] > first[0]["impact_count"]
    host.close()


def test_a_run_that_starts_later_is_the_same_run_shifted(fmus):
    t0, h = 0.75, 1e-3
    late, early = Host(fmus, 3, start_time=t0), Host(fmus, 3)
    for k in range(400):
        late.step(t0 + k * h, h)
        early.step(k * h, h)
    assert late.errors() == []
    a, b = late.outputs(), early.outputs()
    assert a["impact_count"] == b["impact_count"] > 0
    for name in ("main_displacement", "impactor_velocity", "energy_dissipated"):
        assert a[name] == pytest.approx(b[name], rel=1e-9, abs=1e-15), name
    late.close()
    early.close()


@pytest.mark.parametrize("values, name", [({"m": -1.0}, "m"), ({"d": math.nan}, "d"), ({"voltage_model": 7}, "voltage_model")])
def test_a_bad_start_value_is_named_and_the_first_step_is_an_error(fmus, values, name):
    host = Host(fmus, 3, values)
    with pytest.raises(FMICallException) as refused:
        host.step(0.0, 1e-3)
    assert refused.value.status == fmi3Error
    assert any(f"{name} = " in message for message in host.errors()), host.log
    host.fmu.reset()  # the instance recovers: a fresh start with the defaults
    host.fmu.enterInitializationMode()
    host.fmu.exitInitializationMode()
    host.step(0.0, 1e-3)
    assert math.isfinite(host.outputs()["main_displacement"])
    host.close()


@pytest.mark.parametrize("current, step, words", [(0.0, -1e-3, "must be finite and > 0"), (0.0, math.nan, "finite"),
                                                  (0.5, 1e-3, "must continue from the end")])
def test_a_bad_step_is_an_error_and_the_run_goes_on(fmus, current, step, words):
    host = Host(fmus, 3)
    host.step(0.0, 1e-3)
    with pytest.raises(FMICallException) as refused:
        host.step(current, step)
    assert refused.value.status == fmi3Error and any(words in message for message in host.errors()), host.log
    host.step(1e-3, 1e-3)
    assert math.isfinite(host.outputs()["main_displacement"])
    host.close()


def test_a_non_finite_input_is_an_error_and_the_run_goes_on(fmus):
    host = Host(fmus, 3)
    host.step(0.0, 1e-3)
    host.set(base_velocity=math.inf)
    with pytest.raises(FMICallException):
        host.step(1e-3, 1e-3)
    assert any("base_velocity = inf" in message for message in host.errors())
    host.set(base_velocity=0.0)
    host.step(1e-3, 1e-3)
    assert math.isfinite(host.outputs()["main_displacement"])
    host.close()


def test_a_wrong_access_is_logged_and_never_damages_the_process(fmus):
    host = Host(fmus, 3)
    out = host.variables["main_displacement"].valueReference
    count = host.variables["impact_count"].valueReference
    host.fmu.setFloat64([out], [1.0])
    host.fmu.getInt32([out])
    host.fmu.getFloat64([count])
    host.fmu.getFloat64([9999])
    host.fmu.getBoolean([out])
    for words in ("main_displacement (valueReference", "is of type Float64, not Int32", "is of type Int32, not Float64",
                  "no variable has valueReference=9999", "no variable has this type"):
        assert any(words in message for message in host.errors()), (words, host.log)
    for _ in range(3):  # after exceptions, pythonfmu3's binary would crash here, at a collection
        gc.collect()
        host.step(_time(host), 1e-3)
    assert math.isfinite(host.outputs()["main_displacement"])
    host.close()


def _time(host: Host) -> float:
    return host.fmu.getFloat64([host.variables["time"].valueReference])[0]
