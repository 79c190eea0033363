"""The committed FMU, driven through fmpy as a co-simulation host drives it.

Every behaviour is checked on ``fmus/PiezoImpactDamper.fmu`` itself, against the core
(:class:`piezo_fmu.Simulator`) read through the slave's own table of outputs.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import random
import subprocess
import sys
import sysconfig
from ctypes import byref
from pathlib import Path

import pytest
from fmpy import calloc, extract, free, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Error)
from fmpy.logging import addLoggerProxy

from piezo_fmu import Parameters, Simulator, parameter_info
from piezo_fmu.build import fmus as fmu_build
from piezo_fmu.fmi.variables import OUTPUTS
from piezo_fmu.solver import ENERGY_READINGS
from fmu_host import read_outputs, set_values

ROOT = Path(__file__).resolve().parents[1]
FMU = ROOT / fmu_build.DEFAULT_DEST
STOP_TIME = 2.0
METRICS = ("impact_count", "last_impact_voltage", "voltage_rms", "average_power",
           "damping_inclination", "damping_inclination_ls", "energy_dissipated")


@pytest.fixture(scope="module")
def model_description():
    return read_model_description(str(FMU))


@pytest.fixture(scope="module")
def unzipdir(tmp_path_factory):
    return extract(str(FMU), unzipdir=str(tmp_path_factory.mktemp("fmu")))


def _collect(component, instance_name, status, category, message):
    LOG.append((instance_name.decode("utf-8"), status, message.decode("utf-8")))


#: Every FMU message of this module, by instance. fmpy's logger proxy keeps one logger for the
#: whole process (the last registered), so one collector, alive as long as the module, serves all.
LOG: list[tuple[str, int, str]] = []
CALLBACKS = fmi2CallbackFunctions()
CALLBACKS.logger = fmi2CallbackLoggerTYPE(_collect)
CALLBACKS.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
CALLBACKS.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
addLoggerProxy(byref(CALLBACKS))
INSTANCE_NUMBERS = itertools.count()


def instantiate(unzipdir, model_description, logging_on=True) -> tuple[FMU2Slave, str]:
    name = f"instance{next(INSTANCE_NUMBERS)}"
    fmu = FMU2Slave(guid=model_description.guid, unzipDirectory=unzipdir, instanceName=name,
                    modelIdentifier=model_description.coSimulation.modelIdentifier)
    fmu.instantiate(callbacks=CALLBACKS, loggingOn=logging_on)
    return fmu, name


class Host:
    """One FMU instance, initialized, with debug logging on and its log collected.

    ``step`` advances by ``h`` the way fmpy does: the next point is ``n h``, the step size
    the difference to it.
    """

    def __init__(self, unzipdir, model_description, start_values=None, inputs=None):
        self.variables = {v.name: v for v in model_description.modelVariables}
        self.fmu, self.name = instantiate(unzipdir, model_description)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(**(start_values or {}))
        self.set(**(inputs or {}))
        self.fmu.exitInitializationMode()
        self.t, self.n = 0.0, 0

    @property
    def messages(self) -> list[tuple[int, str]]:
        return [(status, message) for name, status, message in LOG if name == self.name]

    def set(self, **values) -> None:
        set_values(self.fmu, self.variables, **values)

    def outputs(self) -> dict:
        return read_outputs(self.fmu, self.variables)

    def step(self, h: float) -> None:
        t_next = (self.n + 1) * h
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=t_next - self.t)
        self.t, self.n = t_next, self.n + 1

    def run(self, t_end: float, h: float, every: int | None = None) -> list[tuple[float, dict]]:
        """Step with ``h`` to ``t_end``; the outputs at every ``every``-th point (and the last)."""
        self.t, self.n = 0.0, 0
        n_steps = round(t_end / h)
        samples = []
        for k in range(1, n_steps + 1):
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=k * h - self.t)
            self.t = k * h
            if k == n_steps or (every and k % every == 0):
                samples.append((self.t, self.outputs()))
        return samples

    def errors(self) -> list[str]:
        return [message for status, message in self.messages if status >= fmi2Error]

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def core_outputs(params: Parameters, t: float) -> dict:
    """The FMU's outputs computed from the core advanced in one call to ``t``, base at rest."""
    sim = Simulator(params)
    if t > 0:
        sim.advance(t, 0.0, 0.0)
    return outputs_of(sim)


def outputs_of(sim: Simulator) -> dict:
    """The FMU's outputs as the core ``sim`` reads them: each output is the reading of its name,
    0 where the table says so while the reading is NaN (a metric not defined yet)."""
    readings = sim.readings()
    return {spec.name: 0.0 if spec.undefined_is_zero and math.isnan(readings[spec.name]) else readings[spec.name]
            for spec in OUTPUTS}


def assert_outputs_close(actual: dict, expected: dict, rtol: float, scale: dict | None = None):
    """Each output within ``rtol`` of the expected value, relative to the output's own scale."""
    for name, want in expected.items():
        size = max(abs(want), (scale or {}).get(name, 0.0))
        assert abs(actual[name] - want) <= rtol * size, (name, actual[name], want)


# -- the modelDescription (the archive itself: tests/test_fmu_build.py) --------------------------

def test_every_variable_has_a_description_a_defined_unit_and_the_core_defaults(model_description):
    md = model_description
    units = {unit.name for unit in md.unitDefinitions}
    info = parameter_info()
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            assert v.unit in units, v.name
        if v.causality == "parameter":
            assert (v.variability, v.initial) == ("fixed", "exact")
            start = int(v.start) if v.type == "Integer" else float(v.start)
            assert start == info[v.name]["default"], v.name
            assert v.type == "Real" or v.name in ("barrier_mode", "voltage_model")
            if v.type == "Real":
                assert v.unit == info[v.name]["unit"]
    parameters = [v.name for v in md.modelVariables if v.causality == "parameter"]
    assert parameters == list(info)
    assert {"M", "K", "C", "m", "d", "C_eq", "E_b", "L", "t_b", "W_b", "rho_b", "x1", "E_p", "L_p",
            "t_p", "W_p", "rho_p", "g31", "R_load", "p0", "q0", "dp0", "dq0", "barrier_mode",
            "M_eq", "K_eq", "voltage_model", "d31", "eps33"} == set(parameters)


def test_interface_names_types_and_bounds(model_description):
    md = model_description
    by_name = {v.name: v for v in md.modelVariables}
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert inputs == ["base_displacement", "base_velocity"]
    assert outputs == ["main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity",
                       "deflection_left", "deflection_right", "voltage_left", "voltage_right", "base_force",
                       "impact_count", "last_impact_voltage", "voltage_rms", "average_power",
                       "damping_inclination", "energy_dissipated", "energy_balance_error",
                       "harvested_energy", "power_left", "power_right", "harvested_energy_left",
                       "harvested_energy_right", "damping_inclination_ls"]
    calculated = [v.name for v in md.modelVariables if v.causality == "calculatedParameter"]
    assert calculated == ["patch_capacitance", "contact_frequency"]
    assert all((by_name[name].variability, by_name[name].initial) == ("fixed", "calculated") for name in calculated)
    # Each group appended after the earlier ones: the value references of earlier variables did not
    # move (the calculated parameters after the first outputs, the robust DI after them).
    first = [v for v in md.modelVariables if v.causality != "calculatedParameter" and v.name != "damping_inclination_ls"]
    assert max(v.valueReference for v in first) < min(by_name[name].valueReference for name in calculated) < \
        by_name["damping_inclination_ls"].valueReference
    assert (by_name["impact_count"].type, by_name["impact_count"].variability) == ("Integer", "discrete")
    assert by_name["barrier_mode"].type == "Integer"
    assert (by_name["barrier_mode"].min, by_name["barrier_mode"].max) == ("0", "1")
    assert (by_name["voltage_model"].type, by_name["voltage_model"].min, by_name["voltage_model"].max) == \
        ("Integer", "0", "2")
    # (0, inf): FMI has no exclusive bounds, so the least positive double
    assert float(by_name["m"].min) == math.nextafter(0.0, math.inf) and by_name["m"].max is None
    for name in ("voltage_rms", "average_power", "energy_dissipated", "deflection_left", "impact_count"):
        assert float(by_name[name].min) == 0.0, name
    units = {name: by_name[name].unit for name in ("base_displacement", "base_velocity", "voltage_left",
                                                  "base_force", "average_power", "damping_inclination",
                                                  "energy_dissipated", "R_load", "g31", "patch_capacitance",
                                                  "contact_frequency", "harvested_energy_left")}
    assert units == {"base_displacement": "m", "base_velocity": "m/s", "voltage_left": "V", "base_force": "N",
                     "average_power": "W", "damping_inclination": "m/s", "energy_dissipated": "J",
                     "R_load": "Ohm", "g31": "V.m/N", "patch_capacitance": "F", "contact_frequency": "rad/s",
                     "harvested_energy_left": "J"}


def test_capabilities_default_experiment_and_model_structure(model_description):
    md = model_description
    cs = md.coSimulation
    assert cs.canHandleVariableCommunicationStepSize and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    experiment = md.defaultExperiment
    assert (float(experiment.startTime), float(experiment.stopTime), float(experiment.stepSize)) == (0.0, 2.0, 1e-4)
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    calculated = [v for v in md.modelVariables if v.causality == "calculatedParameter"]
    assert [u.variable for u in md.outputs] == outputs
    # FMI 2.0 section 2.2.8: the outputs and the calculated parameters are the initial unknowns,
    # in the order of their indices.
    assert [u.variable for u in md.initialUnknowns] == [v for v in md.modelVariables if v in outputs + calculated]
    assert all(u.dependencies == [] for u in md.outputs)
    assert md.guid.startswith("{") and md.guid.endswith("}")


# -- behaviour -------------------------------------------------------------------------------------

@pytest.mark.parametrize("values", [{}, {"t_p": 0.5e-3, "eps33": 20e-9, "W_p": 0.015, "m": 0.05, "K_eq": 5e4}],
                         ids=["nominal", "changed"])
def test_calculated_parameters_follow_the_start_values_in_closed_form(unzipdir, model_description, values):
    host = Host(unzipdir, model_description, start_values=values)
    by_name = host.variables
    C_p, omega_c = host.fmu.getReal([by_name[name].valueReference for name in ("patch_capacitance", "contact_frequency")])
    host.close()
    params = Parameters(**values)
    # Closed forms (docs/model.md section 5; the reduced mass of the two contact bodies), not the core's code.
    sim = Simulator(params)
    M_eq, K_eq = sim.barrier.M_eq, sim.barrier.K_eq
    mu = 1.0 / (1.0 / (params.M - M_eq) + 1.0 / (params.m + M_eq))
    assert C_p == pytest.approx(params.eps33 * params.W_p * params.L_p / params.t_p, rel=1e-14)
    assert omega_c == pytest.approx(math.sqrt(K_eq / mu), rel=1e-14)
    if not values:  # nominal: 0.34 nF, 818 rad/s, so R_opt ~ 1/(omega_c C_p) ~ 3.6 MOhm
        assert (C_p, omega_c, 1 / (omega_c * C_p)) == pytest.approx((3.407e-10, 818.07, 3.588e6), rel=1e-3)


def test_harvested_energy_per_barrier_adds_up_to_the_total(unzipdir, model_description):
    host = Host(unzipdir, model_description, start_values={"voltage_model": 1, "R_load": 3.6e6})
    (_, final), = host.run(STOP_TIME, 1e-3)
    host.close()
    expected = core_outputs(Parameters(voltage_model=1, R_load=3.6e6), STOP_TIME)
    assert final["harvested_energy_left"] > 0 and final["harvested_energy_right"] > 0
    assert final["harvested_energy_left"] + final["harvested_energy_right"] == \
        pytest.approx(final["harvested_energy"], rel=1e-14)
    assert_outputs_close(final, expected, rtol=1e-12)


def test_any_outputs_read_at_any_step_have_the_bits_of_a_host_that_reads_every_output(unzipdir, model_description):
    """Which outputs a host reads after a step changes nothing it reads: each value is, to the bit,
    the one a host that reads every output gets, the energy ledger's included (an instant at which
    none of those is read is spared their quadratures, and the ledger still books as a full read
    would). Both hosts read after every step (the ledger's rounding follows the instants a host reads
    at, ``Ledger.book_pending``). A third host reads only at the end of each period, as the tests'
    marches with fmpy alone do (``fmpy_march``): the motion it reads there has the same bits. Under
    the harness's first-order hold at 1.25 w_n: impacts every period, a new bracket every step, the
    circuits harvesting."""
    values = {"voltage_model": 1, "R_load": 3.6e6}
    omega, n, amplitude = 1.25 * math.sqrt(1000.0), 64, 1e-3
    h = 2.0 * math.pi / omega / n
    nodes = [amplitude * math.sin(2.0 * math.pi * k / n) for k in range(n + 1)]
    hold = [(nodes[k], (nodes[k + 1] - nodes[k]) / h) for k in range(n)]
    inputs = {"base_displacement": hold[0][0], "base_velocity": hold[0][1]}
    every, some, seldom = (Host(unzipdir, model_description, start_values=values, inputs=inputs) for _ in range(3))
    variables = every.variables
    outputs = [name for name, v in variables.items() if v.causality == "output"]
    energy = [name for name in outputs if name in ENERGY_READINGS]
    motion = [name for name in outputs if name not in ENERGY_READINGS]
    assert len(energy) == 5 and len(motion) == len(outputs) - 5
    rng = random.Random(3)
    reads = {"motion": 0, "energy": 0}
    try:
        for step in range(8 * n):
            y, v = hold[step % n]
            for host in (every, some, seldom):
                host.set(base_displacement=y, base_velocity=v)
                host.step(h)
            expected = every.outputs()
            if step % n == n - 1:
                for name in motion:
                    var = variables[name]
                    getter = seldom.fmu.getInteger if var.type == "Integer" else seldom.fmu.getReal
                    value = getter([var.valueReference])[0]
                    assert float(value).hex() == float(expected[name]).hex(), (step, name, value, expected[name])
            kind = rng.choices(list(reads), weights=(4, 1))[0]
            reads[kind] += 1
            chosen = rng.sample(motion, 2) + (rng.sample(energy, 1) if kind == "energy" else [])
            for name in chosen:
                var = variables[name]
                getter = some.fmu.getInteger if var.type == "Integer" else some.fmu.getReal
                value = getter([var.valueReference])[0]
                assert float(value).hex() == float(expected[name]).hex(), (step, name, value, expected[name])
        assert expected["impact_count"] >= 8 and expected["harvested_energy"] > 0
        assert min(reads.values()) > 80
    finally:
        for host in (every, some, seldom):
            host.close()


def test_nominal_case_through_fmpy_equals_the_core():
    result = simulate_fmu(str(FMU), stop_time=STOP_TIME, output_interval=1e-4)
    assert len(result) == 20001
    final = {name: float(result[name][-1]) for name in result.dtype.names}
    assert final["time"] == pytest.approx(STOP_TIME, rel=1e-15)
    expected = core_outputs(Parameters(), final["time"])
    assert final["impact_count"] == expected["impact_count"] > 0
    assert expected["damping_inclination"] > 0 and expected["voltage_rms"] > 0
    scale = {"energy_balance_error": expected["energy_dissipated"]}
    assert_outputs_close(final, expected, rtol=1e-12, scale=scale)


COMMUNICATION_STEPS = (1e-5, 1e-4, 1e-2, 0.5)


@pytest.fixture(scope="module")
def step_runs(unzipdir, model_description):
    """Nominal case, base at rest, to 2 s at each communication step: outputs at ~16 points."""
    runs = {}
    for h in COMMUNICATION_STEPS:
        host = Host(unzipdir, model_description)
        runs[h] = host.run(STOP_TIME, h, every=max(1, round(STOP_TIME / h) // 16))
        host.close()
    return runs


@pytest.mark.parametrize("h", COMMUNICATION_STEPS)
def test_outputs_at_every_communication_point_are_the_core_state_at_that_time(step_runs, h):
    samples = step_runs[h]
    assert len(samples) >= 4 and samples[-1][0] == pytest.approx(STOP_TIME, rel=1e-15)
    params = Parameters()
    scale = {"main_displacement": 1e-2, "impactor_displacement": 1e-2, "main_velocity": 1e-1,
             "impactor_velocity": 1e-1, "deflection_left": 1e-4, "deflection_right": 1e-4,
             "voltage_left": 1e3, "voltage_right": 1e3, "base_force": 10.0, "energy_balance_error": 1e-1}
    for t, outputs in samples:
        expected = core_outputs(params, t)
        assert outputs["impact_count"] == expected["impact_count"], t
        assert_outputs_close(outputs, expected, rtol=1e-12, scale=scale)


def test_metrics_do_not_depend_on_the_communication_step(step_runs):
    finals = {h: samples[-1][1] for h, samples in step_runs.items()}
    reference = finals[1e-4]
    assert reference["impact_count"] > 10 and reference["damping_inclination_ls"] > 0
    for h, final in finals.items():
        assert final["impact_count"] == reference["impact_count"], h
        for name in METRICS:
            assert final[name] == pytest.approx(reference[name], rel=1e-9, abs=0.0), (h, name)


def test_variable_communication_steps_give_the_core_state(unzipdir, model_description):
    host = Host(unzipdir, model_description)
    steps = [1e-3, 3.7e-2, 1e-6, 0.2, 5e-4, 0.31, 2e-5, 0.05] * 3
    t = 0.0
    for h in steps:
        host.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        t += h
    expected = core_outputs(Parameters(), t)
    assert expected["impact_count"] > 5
    assert_outputs_close(host.outputs(), expected, rtol=1e-12, scale={"energy_balance_error": 1.0})
    host.close()


def test_a_host_that_sets_only_the_displacement_gets_a_zero_order_hold(unzipdir, model_description):
    h, Y, omega = 1e-3, 2e-3, 31.0
    host = Host(unzipdir, model_description)
    sim = Simulator(Parameters())
    for k in range(300):
        y = Y * math.sin(omega * k * h)
        host.set(base_displacement=y)
        host.step(h)
        sim.advance((k + 1) * h, y, 0.0)
    expected = outputs_of(sim)
    assert_outputs_close(host.outputs(), expected, rtol=1e-12, scale={"energy_balance_error": 1.0})
    host.close()


def test_base_velocity_input_moves_the_base_linearly_within_a_step(unzipdir, model_description):
    h, Y, omega = 1e-3, 2e-3, 31.0
    host = Host(unzipdir, model_description)
    sim = Simulator(Parameters())
    for k in range(300):
        t = k * h
        y, v = Y * math.sin(omega * t), Y * omega * math.cos(omega * t)
        host.set(base_displacement=y, base_velocity=v)
        host.step(h)
        sim.advance((k + 1) * h, y, v)
    expected = outputs_of(sim)
    assert_outputs_close(host.outputs(), expected, rtol=1e-12, scale={"energy_balance_error": 1.0})
    host.close()


def run_outputs(host: Host, t_from: float, t_to: float, h: float) -> list[dict]:
    out = []
    t = t_from
    for k in range(1, round((t_to - t_from) / h) + 1):
        t_next = t_from + k * h
        host.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=t_next - t)
        t = t_next
        out.append(host.outputs())
    return out


@pytest.mark.parametrize("call, message", [
    (lambda fmu, out: fmu.setReal([out], [1.0]), "main_displacement (valueReference={out}, causality output) cannot be set"),
    (lambda fmu, out: fmu.getInteger([out]), "main_displacement (valueReference={out}) is of type Real, not Integer"),
    (lambda fmu, out: fmu.getReal([9999]), "no variable has valueReference=9999"),
    (lambda fmu, out: fmu.getBoolean([out]), "main_displacement (valueReference={out}) is of type Real, not Boolean"),
], ids=["set an output", "an Integer read of a Real", "an unknown reference", "a Boolean read"])
def test_a_wrong_access_is_an_error_from_that_call_with_a_message_naming_it(unzipdir, model_description, call, message):
    # The slave's own accessors (pythonfmu's variable objects are made for the model description
    # only): what pythonfmu's accessors refuse, they refuse, as an error, and the process goes on.
    host = Host(unzipdir, model_description)
    out = host.variables["main_displacement"].valueReference
    with pytest.raises(FMICallException) as refused:
        call(host.fmu, out)
    assert refused.value.status == fmi2Error
    assert any(message.format(out=out) in text for status, text in host.messages if status == fmi2Error), host.messages
    host.step(1e-3)  # the instance goes on
    assert math.isfinite(host.outputs()["main_displacement"])
    again = Host(unzipdir, model_description)  # a new instance in the same process works
    again.step(1e-3)
    assert math.isfinite(again.outputs()["main_displacement"])
    again.close()


def test_get_and_set_state_reruns_bit_identically(unzipdir, model_description):
    host = Host(unzipdir, model_description)
    run_outputs(host, 0.0, 0.3, 1e-3)
    state = host.fmu.getFMUstate()
    first = run_outputs(host, 0.3, 0.6, 1e-3)
    host.fmu.setFMUstate(state)
    again = run_outputs(host, 0.3, 0.6, 1e-3)
    assert again == first
    host.fmu.setFMUstate(state)  # a state can be set more than once
    assert run_outputs(host, 0.3, 0.6, 1e-3) == first
    host.fmu.freeFMUstate(state)
    assert first[-1]["impact_count"] > first[0]["impact_count"]
    host.close()


def test_serialized_state_restores_the_full_state_in_a_new_instance(unzipdir, model_description):
    host = Host(unzipdir, model_description, start_values={"m": 0.15})
    run_outputs(host, 0.0, 0.25, 1e-3)
    state = host.fmu.getFMUstate()
    data = host.fmu.serializeFMUstate(state)
    host.fmu.freeFMUstate(state)
    json.loads(bytes(data))  # JSON-safe
    first = run_outputs(host, 0.25, 0.5, 1e-3)
    host.close()

    other = Host(unzipdir, model_description)  # defaults: the state carries m = 0.15
    restored = other.fmu.deSerializeFMUstate(data)
    other.fmu.setFMUstate(restored)
    other.fmu.freeFMUstate(restored)
    assert run_outputs(other, 0.25, 0.5, 1e-3) == first
    other.close()


def test_two_instances_with_different_parameters_give_what_each_gives_alone(unzipdir, model_description, tmp_path):
    designs = [{"x1": 10e-3, "m": 0.2, "d": 10e-3}, {"x1": 30e-3, "m": 0.02, "d": 3e-3}]
    alone = []
    for values in designs:
        host = Host(unzipdir, model_description, start_values=values)
        alone.append(run_outputs(host, 0.0, 0.5, 1e-3))
        host.close()
    # The second instance comes from a second copy of the FMU, as a host with two FMUs has.
    other_dir = extract(str(FMU), unzipdir=str(tmp_path / "copy"))
    hosts = [Host(unzipdir, model_description, start_values=designs[0]),
             Host(other_dir, model_description, start_values=designs[1])]
    together = [[], []]
    for k in range(1, 501):
        for host, out in zip(hosts, together):
            out.extend(run_outputs_from(host, k, 1e-3))
    for host in hosts:
        host.close()
    assert together == alone
    assert alone[0][-1] != alone[1][-1]
    for values, outputs in zip(designs, alone):
        expected = core_outputs(Parameters(**values), 0.5)
        assert_outputs_close(outputs[-1], expected, rtol=1e-12, scale={"energy_balance_error": 1.0})


def run_outputs_from(host: Host, k: int, h: float) -> list[dict]:
    """Step ``k`` of size ``h`` (from ``(k - 1) h``) and the outputs after it."""
    t = (k - 1) * h
    host.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=k * h - t)
    return [host.outputs()]


# -- errors: logged, non-OK, recoverable -----------------------------------------------------------

@pytest.mark.parametrize("values, name", [
    ({"m": -1.0}, "m"),
    ({"x1": 75e-3}, "x1"),
    ({"d": 0.0}, "d"),
    ({"barrier_mode": 2}, "barrier_mode"),
    ({"M": 1e-3}, "M"),
])
def test_bad_parameter_is_an_error_from_exit_initialization_named_and_reset_recovers(unzipdir, model_description,
                                                                                       values, name):
    fmu, instance = instantiate(unzipdir, model_description)
    host = Host.__new__(Host)  # the log of this instance, read as Host reads it
    host.fmu, host.name = fmu, instance
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    set_values(fmu, {v.name: v for v in model_description.modelVariables}, **values)
    with pytest.raises(FMICallException) as refused:
        fmu.exitInitializationMode()
    assert refused.value.status == fmi2Error
    assert any(f"{name} = " in message for message in host.errors()), host.messages
    with pytest.raises(FMICallException) as step_refused:  # the instance is in its error state
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    assert step_refused.value.status == fmi2Error
    fmu.reset()  # the same instance, back to the default start values
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    assert math.isfinite(read_outputs(fmu, {v.name: v for v in model_description.modelVariables})["main_displacement"])
    fmu.terminate()
    fmu.freeInstance()


@pytest.mark.parametrize("inputs", [
    {"base_displacement": math.nan}, {"base_displacement": math.inf}, {"base_velocity": -math.inf},
    {"base_velocity": math.nan},
])
def test_a_non_finite_input_is_an_error_from_the_setter_and_changes_nothing(unzipdir, model_description, inputs):
    host = Host(unzipdir, model_description)
    reference = Host(unzipdir, model_description)
    run_outputs(host, 0.0, 0.1, 1e-3)
    expected = run_outputs(reference, 0.0, 0.2, 1e-3)[-1]
    with pytest.raises(FMICallException) as refused:
        host.set(**inputs)
    assert refused.value.status == fmi2Error
    name, = inputs
    assert any(f"{name} = " in message and "is not finite; allowed range (-inf, inf)" in message
               for message in host.errors()), host.messages
    assert run_outputs(host, 0.1, 0.2, 1e-3)[-1] == expected  # the refused value changed nothing
    host.close()
    reference.close()


def test_a_non_finite_parameter_is_an_error_from_the_setter_naming_its_range(unzipdir, model_description):
    fmu, instance = instantiate(unzipdir, model_description)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    with pytest.raises(FMICallException) as refused:
        set_values(fmu, {v.name: v for v in model_description.modelVariables}, m=math.nan)
    assert refused.value.status == fmi2Error
    assert any(message == "m = nan is not finite; allowed range (0, inf) kg"
               for entry, status, message in LOG if entry == instance and status == fmi2Error)
    fmu.exitInitializationMode()  # the default m holds
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    fmu.terminate()
    fmu.freeInstance()


@pytest.mark.parametrize("current, step, words", [
    (0.1, 0.0, "step size"),
    (0.1, -1e-3, "step size"),
    (0.1, math.nan, "step size"),
    (0.25, 1e-3, "continue"),
    (0.05, 1e-3, "continue"),
])
def test_bad_step_is_refused_and_the_instance_recovers(unzipdir, model_description, current, step, words):
    host = Host(unzipdir, model_description)
    reference = Host(unzipdir, model_description)
    run_outputs(host, 0.0, 0.1, 1e-3)
    expected = run_outputs(reference, 0.0, 0.2, 1e-3)[-1]
    with pytest.raises(FMICallException) as refused:
        host.fmu.doStep(currentCommunicationPoint=current, communicationStepSize=step)
    assert refused.value.status == fmi2Error
    assert any(words in message for message in host.errors()), host.messages
    assert run_outputs(host, 0.1, 0.2, 1e-3)[-1] == expected
    host.close()
    reference.close()


def test_setting_a_parameter_after_initialization_is_an_error_from_the_setter(unzipdir, model_description):
    host = Host(unzipdir, model_description)
    host.step(1e-3)
    with pytest.raises(FMICallException) as refused:
        host.set(m=0.5)
    assert refused.value.status == fmi2Error
    assert any("parameter m is fixed: it cannot be set to 0.5 after initialization" in message
               for message in host.errors()), host.messages
    with pytest.raises(FMICallException):  # the instance is in its error state until a reset
        host.step(1e-3)
    host.set(m=0.1)  # setting the value it has is no change, hence no error
    host.close()


def test_errors_reach_the_host_without_debug_logging(unzipdir, model_description):
    """pythonfmu alone logs nothing, its errors included, unless debug logging is on; the FMU's
    loader passes on every message of status Warning or worse (tests/test_loader.py shows that
    information still needs debug logging)."""
    fmu, name = instantiate(unzipdir, model_description, logging_on=False)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    with pytest.raises(FMICallException):
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=-1.0)
    logged = [(status, message) for entry_name, status, message in LOG if entry_name == name]
    assert logged == [(fmi2Error, "communication step size = -1.0 s must be finite and > 0")]
    fmu.terminate()
    fmu.freeInstance()


def test_reset_returns_to_the_start_values(unzipdir, model_description):
    host = Host(unzipdir, model_description)
    first = run_outputs(host, 0.0, 0.05, 1e-3)
    host.fmu.reset()
    host.fmu.setupExperiment(startTime=0.0)
    host.fmu.enterInitializationMode()
    host.fmu.exitInitializationMode()
    assert run_outputs(host, 0.0, 0.05, 1e-3) == first
    host.close()


# -- the command line and the bundle ------------------------------------------------------------

def fmpy_command() -> list[str]:
    script = Path(sys.executable).with_name("fmpy")
    return [str(script)] if script.exists() else [sys.executable, "-m", "fmpy"]


def test_fmpy_info_on_the_command_line():
    done = subprocess.run(fmpy_command() + ["info", str(FMU)], capture_output=True, text=True, check=True)
    for word in ("PiezoImpactDamper", "base_displacement", "voltage_rms", "impact_count", "R_load"):
        assert word in done.stdout


def test_fmpy_simulate_on_the_command_line_with_output_interval_and_start_values(tmp_path):
    out = tmp_path / "result.csv"
    subprocess.run(fmpy_command() + ["simulate", str(FMU), "--stop-time", "0.5", "--output-interval", "1e-3",
                                     "--start-values", "m", "0.2", "d", "0.01", "--output-file", str(out)],
                   capture_output=True, text=True, check=True, cwd=tmp_path)
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 501
    expected = core_outputs(Parameters(m=0.2, d=0.01), 0.5)
    final = {name: float(value) for name, value in rows[-1].items()}
    assert float(rows[-1]["time"]) == 0.5
    assert final["impact_count"] == expected["impact_count"]
    # The CSV holds each value to about 16 digits.
    assert_outputs_close(final, expected, rtol=1e-9, scale={"energy_balance_error": 1.0})


def test_the_fmu_runs_on_its_own_bundle_with_only_numpy(tmp_path):
    """A host without piezo_fmu installed (no .pth processing: ``-S``) runs the FMU's copy, and
    needs numpy only: scipy is made unimportable in that host."""
    sites = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    script = f"""
import sys, json, importlib.abc
sys.path.extend({sites!r})
class NoScipy(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] == "scipy":
            raise ImportError("this host has no scipy")
sys.meta_path.insert(0, NoScipy())
import fmpy
result = fmpy.simulate_fmu({str(FMU)!r}, stop_time=0.3, output_interval=1e-3)
core = sys.modules["piezo_fmu"].__file__
print(json.dumps({{"core": core, "impact_count": int(result["impact_count"][-1]),
                  "p": float(result["main_displacement"][-1]), "scipy": "scipy" in sys.modules}}))
"""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-S", "-c", script], capture_output=True, text=True, check=True,
                          cwd=tmp_path, env=env)
    reply = json.loads(done.stdout.strip().splitlines()[-1])
    assert "resources" in Path(reply["core"]).parts and str(ROOT / "src") not in reply["core"]
    assert reply["scipy"] is False
    expected = core_outputs(Parameters(), 0.3)
    assert reply["impact_count"] == expected["impact_count"]
    assert reply["p"] == pytest.approx(expected["main_displacement"], rel=1e-12)
