"""The circuit of the piezoelectric patches as the FMU states it: its calculated constants."""

from __future__ import annotations

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
    return {
        "patch_capacitance_F": capacitance,
        "contact_frequency_rad_per_s": omega,
        "R_opt_estimate_ohm": 1.0 / (omega * capacitance),
    }
