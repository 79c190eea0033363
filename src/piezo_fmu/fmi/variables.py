"""The FMU's variables, once, for every FMI interface: names, types, causalities, units, bounds,
descriptions and start values, and how a co-simulation reads each output from the core.

Every interface is built from :data:`VARIABLES`: the FMI 2.0 co-simulation slave
(:mod:`piezo_fmu.fmi.fmi2`), the FMI 3.0 one (:mod:`piezo_fmu.fmi.fmi3`), and the build, which
writes units, bounds and structure into each modelDescription (:mod:`piezo_fmu.build`). The
value reference of a variable is its index in the table; groups were appended over time so that
no value reference ever moved.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple, Optional

from piezo_fmu import parameter_info


class Variable(NamedTuple):
    """One FMU variable: what the modelDescription says of it and how to read it from the core.

    ``unit``, ``min`` and ``max`` are written by :mod:`piezo_fmu.build` (pythonfmu writes
    none of them). An output's value is the core's reading of the same name
    (:meth:`piezo_fmu.Simulator.readings`), 0 where ``undefined_is_zero`` and the reading is NaN
    (a metric not defined yet); ``read`` maps the :class:`piezo_fmu.Damper` to a calculated
    parameter's value.
    """

    name: str
    type: str  # "Real" or "Integer"
    causality: str  # "parameter", "input", "output", "calculatedParameter" (FMI 3.0 also "independent", "local")
    unit: Optional[str]  # None for Integer variables: FMI 2.0 gives Integer no unit
    description: str
    min: Optional[float] = None
    max: Optional[float] = None
    start: Optional[float] = None  # parameters and inputs only
    read: Optional[Callable] = None  # calculated parameters only
    undefined_is_zero: bool = False  # outputs only


def _declared(limit: float, open_: bool, toward: float) -> Optional[float]:
    """The ``min`` (``toward`` = +inf) or ``max`` (-inf) that declares a bound end exactly.

    FMI has no exclusive bounds: an open end is declared as the nearest double inside it, so
    that the doubles the modelDescription allows are exactly those the FMU accepts (``m`` in
    (0, inf) declares ``min="5e-324"``, the least positive double). A host that trusts
    ``min``/``max`` foresees every refusal of a single value.
    """
    if not math.isfinite(limit):
        return None
    return math.nextafter(limit, toward) if open_ else limit


def _parameter_variables() -> tuple:
    """Every core parameter, under its own name, unit, description, bound and default.

    A parameter whose default is an ``int`` (``barrier_mode``) is an FMI Integer, the rest Real.
    """
    table = []
    for name, info in parameter_info().items():
        bound = info["bound"]
        is_integer = type(info["default"]) is int
        table.append(Variable(
            name=name,
            type="Integer" if is_integer else "Real",
            causality="parameter",
            unit=None if is_integer else info["unit"],
            description=info["description"],
            min=_declared(bound.lo, bound.lo_open, math.inf),
            max=_declared(bound.hi, bound.hi_open, -math.inf),
            start=info["default"],
        ))
    return tuple(table)


INPUTS = (
    Variable("base_displacement", "Real", "input", "m",
             "Base displacement y at the start of the step; within a step y = y_k + v_k (t - t_k)",
             start=0.0),
    Variable("base_velocity", "Real", "input", "m/s",
             "Base velocity v_b, constant within a step (leave at 0 for a zero-order hold of y)",
             start=0.0),
)

_FIRST_OUTPUTS = (
    Variable("main_displacement", "Real", "output", "m",
             "Absolute displacement p of the main mass"),
    Variable("main_velocity", "Real", "output", "m/s",
             "Absolute velocity dp/dt of the main mass"),
    Variable("impactor_displacement", "Real", "output", "m",
             "Absolute displacement q of the impact mass"),
    Variable("impactor_velocity", "Real", "output", "m/s",
             "Absolute velocity dq/dt of the impact mass"),
    Variable("deflection_left", "Real", "output", "m",
             "Tip deflection of the left barrier (r = -d/2); 0 while not in contact",
             min=0.0),
    Variable("deflection_right", "Real", "output", "m",
             "Tip deflection of the right barrier (r = +d/2); 0 while not in contact",
             min=0.0),
    Variable("voltage_left", "Real", "output", "V",
             "Voltage of the left barrier's piezoelectric patch (voltage_model 0: quasi-static, eqs. 25-28, "
             ">= 0; 1 and 2: across the load, signed)"),
    Variable("voltage_right", "Real", "output", "V",
             "Voltage of the right barrier's piezoelectric patch (voltage_model 0: quasi-static, eqs. 25-28, "
             ">= 0; 1 and 2: across the load, signed)"),
    Variable("base_force", "Real", "output", "N",
             "Force the device exerts on its base (spring K and damper C of the main mass), along +x"),
    Variable("impact_count", "Integer", "output", None,
             "Number of impacts (contact onsets) so far, both barriers", min=0),
    Variable("last_impact_voltage", "Real", "output", "V",
             "Peak voltage of the latest completed impact (eq. 28); 0 before the first", min=0.0),
    Variable("voltage_rms", "Real", "output", "V",
             "RMS of the peak voltages of the impacts completed so far (eq. 30)", min=0.0),
    Variable("average_power", "Real", "output", "W",
             "Average power V_rms^2 / R_load (eq. 30)", min=0.0),
    Variable("damping_inclination", "Real", "output", "m/s",
             "Damping inclination (P1 - P2) / (t2 - t1) from the first two maxima of p (eq. 29); "
             "0 until two maxima exist",
             undefined_is_zero=True),
    Variable("energy_dissipated", "Real", "output", "J",
             "Energy dissipated since the start (damping, contact, barrier capture and release)",
             min=0.0),
    Variable("energy_balance_error", "Real", "output", "J",
             "Energy ledger residual: energy now - (initial energy + work by the base - dissipated); "
             "0 to rounding"),
    Variable("harvested_energy", "Real", "output", "J",
             "Energy harvested in the loads of both barriers since the start, integral of V^2/R_load dt "
             "(voltage_model 1 and 2; 0 under the quasi-static model 0, an open-circuit voltage)",
             min=0.0),
    Variable("power_left", "Real", "output", "W",
             "Instantaneous power V^2/R_load into the left barrier's load (0 under voltage_model 0)",
             min=0.0),
    Variable("power_right", "Real", "output", "W",
             "Instantaneous power V^2/R_load into the right barrier's load (0 under voltage_model 0)",
             min=0.0),
    Variable("harvested_energy_left", "Real", "output", "J",
             "Energy harvested in the left barrier's load since the start, integral of V^2/R_load dt "
             "(0 under voltage_model 0)",
             min=0.0),
    Variable("harvested_energy_right", "Real", "output", "J",
             "Energy harvested in the right barrier's load since the start, integral of V^2/R_load dt "
             "(0 under voltage_model 0)",
             min=0.0),
)

#: Quantities the FMU derives from its parameters (FMI calculatedParameter): what a designer
#: needs to choose a load, ``R_opt ~ 1 / (contact_frequency patch_capacitance)``.
CALCULATED = (
    Variable("patch_capacitance", "Real", "calculatedParameter", "F",
             "Capacitance C_p = eps33 W_p L_p / t_p of each barrier's piezoelectric patch (docs/model.md section 5)",
             min=0.0, read=lambda damper: damper.barrier.C_p),
    Variable("contact_frequency", "Real", "calculatedParameter", "rad/s",
             "Undamped angular frequency sqrt(K_eq / mu) of the relative motion in contact, mu the reduced "
             "mass of M - M_eq and m + M_eq (short-circuited patch)",
             min=0.0, read=lambda damper: damper.contact_frequency),
)

#: Outputs added after the calculated parameters (appended, so that no value reference moved).
_LATER_OUTPUTS = (
    Variable("damping_inclination_ls", "Real", "output", "m/s",
             "Robust damping inclination: minus the least-squares slope of the positive maxima of p that "
             "follow an impact (a companion of eq. 29, insensitive to a double maximum); 0 until two such "
             "maxima exist",
             undefined_is_zero=True),
)

#: The whole table, in value-reference order: parameters, inputs, outputs, calculated parameters,
#: then the later outputs (each group appended, so that the earlier value references stay as they were).
VARIABLES = _parameter_variables() + INPUTS + _FIRST_OUTPUTS + CALCULATED + _LATER_OUTPUTS
#: Every output, in value-reference order.
OUTPUTS = tuple(spec for spec in VARIABLES if spec.causality == "output")

#: The independent variable FMI 3.0 requires, after the table.
TIME = Variable("time", "Real", "independent", "s", "Simulation time")

#: Model Exchange (FMI 3.0; :mod:`piezo_fmu.fmi.me`): the continuous states, in order. The
#: displacements and velocities and the harvested energies are outputs of the table (the output is
#: the state, as ``h`` and ``v`` in the FMI reference model BouncingBall); the circuit voltages and
#: the other quadratures of the energy ledger are locals below.
STATES = ("main_displacement", "main_velocity", "impactor_displacement", "impactor_velocity",
          "circuit_voltage_left", "circuit_voltage_right", "energy_dissipated_C", "energy_dissipated_Ceq",
          "energy_work_base", "harvested_energy_left", "harvested_energy_right", "energy_converted")
#: The event indicators, in order; ``main_velocity`` (its falling zeros are the maxima of p) is an output.
INDICATORS = ("gap_right", "gap_left", "deflection_rate", "main_velocity", "voltage_rate")
#: The unit of the derivative of a state of each unit.
_RATE_UNITS = {"m": "m/s", "m/s": "m/s2", "V": "V/s", "J": "W"}

_STATE_LOCALS = (
    Variable("circuit_voltage_left", "Real", "local", "V",
             "Voltage across the left barrier's load as a continuous state (voltage_model 1 and 2; "
             "0 under voltage_model 0, whose voltage_left is k_V times the deflection)"),
    Variable("circuit_voltage_right", "Real", "local", "V",
             "Voltage across the right barrier's load as a continuous state (voltage_model 1 and 2; "
             "0 under voltage_model 0, whose voltage_right is k_V times the deflection)"),
    Variable("energy_dissipated_C", "Real", "local", "J",
             "Energy dissipated in the main damper C since the start, integral of C (p' - v_b)^2 dt", min=0.0),
    Variable("energy_dissipated_Ceq", "Real", "local", "J",
             "Energy dissipated in the contact damping C_eq since the start, integral of C_eq delta'^2 dt", min=0.0),
    Variable("energy_work_base", "Real", "local", "J",
             "Work done by the base on the device since the start, -integral of v_b (K (p - y) + C (p' - v_b)) dt"),
    Variable("energy_converted", "Real", "local", "J",
             "Energy the barriers fed their circuits since the start, integral of chi V delta' dt "
             "(voltage_model 1 and 2; 0 under 0)"),
)
_INDICATOR_LOCALS = (
    Variable("gap_right", "Real", "local", "m",
             "Event indicator q - p - d/2: negative in free flight, the right barrier's deflection in contact "
             "with it; its rising zero is a contact onset, its falling zero a separation; within rounding of 0 "
             "it reads the rounding level, signed as the phase"),
    Variable("gap_left", "Real", "local", "m",
             "Event indicator p - q - d/2: negative in free flight, the left barrier's deflection in contact "
             "with it; its rising zero is a contact onset, its falling zero a separation; within rounding of 0 "
             "it reads the rounding level, signed as the phase"),
    Variable("deflection_rate", "Real", "local", "m/s",
             "Event indicator: the deflection rate delta' of the barrier in contact, whose falling zero is the "
             "peak deflection (V_i under voltage_model 0); 1 in free flight; within rounding of 0 it reads the "
             "rounding level, signed as the last event found it heading"),
    Variable("voltage_rate", "Real", "local", "V/s",
             "Event indicator: dV/dt of the barrier in contact under voltage_model 1 and 2, whose zeros are "
             "the candidates for the peak |V| (V_i); 1 in free flight and under voltage_model 0; within "
             "rounding of 0 it reads the rounding level, signed as at the last event"),
)


def _derivative_rows() -> tuple:
    units = {spec.name: spec.unit for spec in VARIABLES + _STATE_LOCALS}
    return tuple(Variable(f"der({name})", "Real", "local", _RATE_UNITS[units[name]], f"Time derivative of {name}")
                 for name in STATES)


#: The variables only Model Exchange needs (FMI 3.0 locals, after ``time``): the states that are not
#: outputs, the state derivatives ``der(x)``, the event indicators that are not outputs, and the
#: discrete state (the phase).
MODEL_EXCHANGE = _STATE_LOCALS + _derivative_rows() + _INDICATOR_LOCALS + (
    Variable("contact_phase", "Integer", "local", None,
             "Discrete state: 0 in free flight, +1 in contact with the right barrier, -1 with the left one",
             min=-1, max=1),
)
#: The FMI 3.0 FMU's variables in value-reference order: the table, ``time``, the Model Exchange locals.
FMI3_VARIABLES = VARIABLES + (TIME,) + MODEL_EXCHANGE

#: The FMI 2.0 type of each variable, by value reference ("Real" or "Integer").
KINDS = tuple(spec.type for spec in VARIABLES)
#: The value references of each FMI 2.0 type.
REFERENCES = {kind: frozenset(vr for vr, k in enumerate(KINDS) if k == kind) for kind in ("Real", "Integer")}
#: The value references by name.
BY_NAME = {spec.name: vr for vr, spec in enumerate(VARIABLES)}
#: The variability of each (causality, type) of the table, by its FMI name (the same in FMI 2.0
#: and FMI 3.0).
VARIABILITY = {("parameter", "Real"): "fixed", ("parameter", "Integer"): "fixed", ("input", "Real"): "continuous",
               ("output", "Real"): "continuous", ("output", "Integer"): "discrete",
               ("calculatedParameter", "Real"): "fixed", ("independent", "Real"): "continuous",
               ("local", "Real"): "continuous", ("local", "Integer"): "discrete"}
