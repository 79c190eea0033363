"""The circuit of the piezoelectric patches as the FMU states it: its calculated constants."""

from __future__ import annotations

import math

from fmpy.fmi1 import FMICallException

from .fmu import Instance


#: The calculated parameters behind the estimate R_opt ~ 1 / (omega_c C_p).
CONSTANTS = ("patch_capacitance", "contact_frequency")


def circuit_constants(instance: Instance, values: dict) -> dict:
    """``C_p``, ``omega_c`` (from the FMU, initialized with ``values``) and the estimate
    ``R_opt = 1 / (omega_c C_p)``."""
    try:
        instance.start(values)
    except FMICallException as error:
        raise instance.failure(error) from None
    read = instance.read(CONSTANTS)
    capacitance, omega = float(read["patch_capacitance"]), float(read["contact_frequency"])
    product = omega * capacitance
    return {
        "patch_capacitance_F": capacitance,
        "contact_frequency_rad_per_s": omega,
        "R_opt_estimate_ohm": 1.0 / product if product != 0.0 else math.inf,
    }


def default_load(instance: Instance, values: dict) -> float:
    """The default load of the studies of the forced response: ``R_opt`` (:func:`circuit_constants`)
    to 6 digits; refused as :func:`optimum_load` refuses it."""
    return optimum_load(instance, values, digits=6)


def optimum_load(instance: Instance, values: dict, digits: int | None = None) -> float:
    """``R_opt`` (:func:`circuit_constants`), to ``digits`` significant digits if given; refused
    (:class:`~piezo_fmu_harness.spec.UsageError`) when the patch's values leave it no finite
    resistance > 0 (a capacitance of 0 or inf F in double precision)."""
    from .spec import UsageError

    constants = circuit_constants(instance, values)
    load = constants["R_opt_estimate_ohm"]
    if digits is not None:
        load = float(f"{load:.{digits}g}")
    if not 0.0 < load < math.inf:
        shown = ", ".join(f"{name} = {value!r}" for name, value in values.items())
        raise UsageError(f"--load: the default load R_load = 1/(omega_c C_p) = {load:g} Ohm is out of its allowed "
                         f"range (0, inf) Ohm with {shown} (C_p = {constants['patch_capacitance_F']:g} F, omega_c = "
                         f"{constants['contact_frequency_rad_per_s']:g} rad/s): give the load with --load OHM")
    return load
