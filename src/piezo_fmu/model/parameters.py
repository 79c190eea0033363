"""Parameters of the piezo-impact damper, in SI units, under the paper's symbols.

The defaults are the nominal case of docs/model.md section 7 (Table 1 of Afsharfard and
Farshidianfar, 2014, with ``p(0) = q(0) = 10 mm`` and ``R_L = 52 kOhm``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from .barrier import DERIVED, EXPLICIT, PRINTED_K_EQ, PRINTED_M_EQ, derive_barrier
from .voltage import CIRCUIT, COUPLED, QUASI_STATIC

#: Under ``voltage_model = 2`` the electrical rate ``1 / (R_load C_p)`` may exceed the fastest
#: mechanical rate of a contact by at most this factor: the coupled contact is integrated with
#: brackets of ``THETA R_load C_p`` (``propagation.py``), so a contact costs about this many of them.
MAX_COUPLED_STIFFNESS = 1e4


@dataclass(frozen=True)
class Bound:
    """Allowed range of one parameter: ``lo < value`` (or ``<=``) and ``value < hi`` (or ``<=``)."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = True
    hi_open: bool = True

    def contains(self, value: float) -> bool:
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return above and below

    def describe(self) -> str:
        left = "(" if self.lo_open else "["
        right = ")" if self.hi_open else "]"
        return f"{left}{self.lo:g}, {self.hi:g}{right}"


POSITIVE = Bound(0.0, math.inf)
NON_NEGATIVE = Bound(0.0, math.inf, lo_open=False)
FINITE = Bound()


def _p(default: float, unit: str, description: str, bound: Bound = POSITIVE):
    return field(default=default, metadata={"unit": unit, "description": description, "bound": bound})


@dataclass(frozen=True)
class Parameters:
    """Every Table 1 quantity, the load, the initial conditions, the barrier mode, and the
    patch's circuit constants with the voltage model (docs/model.md section 5).

    All values are SI. Construction validates every value and raises ``ValueError``
    naming the parameter, the value and the allowed range.
    """

    # The damper (Table 1, third row).
    M: float = _p(1.0, "kg", "Main mass, including the equivalent tip mass of the barriers")
    K: float = _p(1000.0, "N/m", "Stiffness of the main spring")
    C: float = _p(0.1, "N.s/m", "Viscous damping of the main mass", NON_NEGATIVE)
    m: float = _p(0.1, "kg", "Impact mass")
    d: float = _p(8e-3, "m", "Gap: the impact mass is free while |q - p| < d/2")
    C_eq: float = _p(10.0, "N.s/m", "Equivalent contact damping of a barrier", NON_NEGATIVE)
    # The steel barrier beam (Table 1, first row).
    E_b: float = _p(200e9, "Pa", "Young's modulus of the barrier beam")
    L: float = _p(80e-3, "m", "Length of the barrier beam")
    t_b: float = _p(5e-3, "m", "Thickness of the barrier beam")
    W_b: float = _p(5e-3, "m", "Width of the barrier beam")
    rho_b: float = _p(7850.0, "kg/m3", "Density of the barrier beam")
    x1: float = _p(10e-3, "m", "Distance of the patch from the clamped end", NON_NEGATIVE)
    # The PZT-5H patch (Table 1, second row).
    E_p: float = _p(62e9, "Pa", "Young's modulus of the piezoelectric patch")
    L_p: float = _p(10e-3, "m", "Length of the piezoelectric patch")
    t_p: float = _p(3e-3, "m", "Thickness of the piezoelectric patch")
    W_p: float = _p(4e-3, "m", "Width of the piezoelectric patch")
    rho_p: float = _p(7800.0, "kg/m3", "Density of the piezoelectric patch")
    g31: float = _p(0.008, "V.m/N", "Piezoelectric voltage constant g31 (magnitude)")
    # Electrical load.
    R_load: float = _p(52e3, "Ohm", "Load resistance across each patch")
    # Initial conditions (absolute displacements and velocities).
    p0: float = _p(10e-3, "m", "Initial displacement of the main mass", FINITE)
    q0: float = _p(10e-3, "m", "Initial displacement of the impact mass", FINITE)
    dp0: float = _p(0.0, "m/s", "Initial velocity of the main mass", FINITE)
    dq0: float = _p(0.0, "m/s", "Initial velocity of the impact mass", FINITE)
    # Barrier equivalents: derived from the geometry (0) or taken as given (1).
    barrier_mode: int = field(
        default=DERIVED,
        metadata={"unit": "1", "description": "0: derive M_eq, K_eq from the geometry; 1: use M_eq, K_eq as given",
                  "bound": Bound(DERIVED, EXPLICIT, lo_open=False, hi_open=False)},
    )
    M_eq: float = _p(PRINTED_M_EQ, "kg", "Equivalent tip mass of a barrier (explicit mode only)")
    K_eq: float = _p(PRINTED_K_EQ, "N/m", "Equivalent tip stiffness of a barrier (explicit mode only)")
    # The patch as a circuit element (docs/model.md section 5, eqs. 20-21; voltage_model 1 and 2).
    d31: float = _p(-274e-12, "m/V", "Piezoelectric strain constant d31 of the patch (its magnitude is used)", FINITE)
    eps33: float = _p(25.55e-9, "F/m", "Permittivity eps33 of the patch at constant strain")
    voltage_model: int = field(
        default=QUASI_STATIC,
        metadata={"unit": "1", "description": "0: quasi-static voltage k_V delta (the paper's, eqs. 25-28); "
                                              "1: patch capacitance and load as a circuit, one-way; "
                                              "2: circuit coupled back to the barrier in contact",
                  "bound": Bound(QUASI_STATIC, COUPLED, lo_open=False, hi_open=False)},
    )

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "barrier_mode":
                if isinstance(value, bool) or value not in (DERIVED, EXPLICIT):
                    raise ValueError(f"barrier_mode = {value!r} is not allowed; allowed values are 0 (derived) or 1 (explicit)")
                object.__setattr__(self, f.name, int(value))
                continue
            if f.name == "voltage_model":
                if isinstance(value, bool) or value not in (QUASI_STATIC, CIRCUIT, COUPLED):
                    raise ValueError(f"voltage_model = {value!r} is not allowed; allowed values are 0 (quasi-static), "
                                     "1 (circuit, one-way) or 2 (circuit, coupled)")
                object.__setattr__(self, f.name, int(value))
                continue
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{f.name} = {value!r} is not a number; allowed range {f.metadata['bound'].describe()} {f.metadata['unit']}") from None
            if not math.isfinite(value):
                raise ValueError(f"{f.name} = {value!r} is not finite; allowed range {f.metadata['bound'].describe()} {f.metadata['unit']}")
            bound: Bound = f.metadata["bound"]
            if not bound.contains(value):
                raise ValueError(f"{f.name} = {value!r} {f.metadata['unit']} is out of range; allowed range {bound.describe()}")
            object.__setattr__(self, f.name, value)
        if self.x1 + self.L_p > self.L:
            raise ValueError(
                f"x1 = {self.x1!r} m puts the patch past the beam end: x1 + L_p must be <= L, "
                f"so the allowed range of x1 is [0, {self.L - self.L_p:g}] m")
        # A start on a barrier (|q0 - p0| = d/2, to rounding) is allowed.
        if abs(self.q0 - self.p0) - self.d / 2 > 1e-12 * self.d:
            raise ValueError(
                f"q0 = {self.q0!r} m starts the impact mass outside the gap: |q0 - p0| must be <= d/2, "
                f"so the allowed range of q0 is [{self.p0 - self.d / 2:g}, {self.p0 + self.d / 2:g}] m")
        # M_eq is part of M (docs/model.md section 3), so M must exceed it; checked here for both modes.
        try:
            barrier = derive_barrier(self)
        except (OverflowError, ZeroDivisionError) as error:  # a power beyond double range, or x / 0
            raise self._beyond_double_range("the barrier's equivalents leave", error) from None
        m_eq = barrier.M_eq
        if self.M <= m_eq:
            raise ValueError(
                f"M = {self.M!r} kg must exceed the barrier tip mass M_eq = {m_eq:g} kg; "
                f"allowed range ({m_eq:g}, inf) kg")
        if self.voltage_model == COUPLED:
            # The coupled contact is integrated exactly with brackets of THETA R_load C_p at most:
            # bound the work of a contact rather than let a tiny load stall the run.
            try:
                stiffness = barrier.K_eq + barrier.chi**2 / barrier.C_p
                omega = math.sqrt(stiffness * (1.0 / (self.m + m_eq) + 1.0 / (self.M - m_eq)))
                r_min = 1.0 / (MAX_COUPLED_STIFFNESS * omega * barrier.C_p)
            except (OverflowError, ZeroDivisionError) as error:
                raise self._beyond_double_range("the coupled circuit's stiffness (voltage_model = 1 takes any patch) "
                                                "leaves", error) from None
            if self.R_load < r_min:
                product = self.R_load * barrier.C_p
                raise ValueError(
                    f"R_load = {self.R_load!r} Ohm is too small for voltage_model = 2: the circuit's rate "
                    f"1/(R_load C_p) = {1.0 / product if product else math.inf:.3g} 1/s may exceed the contact's "
                    f"{omega:.3g} rad/s by at most {MAX_COUPLED_STIFFNESS:g} times; allowed range "
                    f"[{r_min:.6g}, inf) Ohm (voltage_model = 1 takes any load)")

    def _beyond_double_range(self, what: str, error: Exception) -> ValueError:
        """The refusal of values beyond double range, ``what`` saying what left it (a subject and its
        verb): the beam's and patch's values moved from their defaults, and the range their
        stiffnesses and masses must keep."""
        moved = ", ".join(f"{name} = {getattr(self, name)!r} {_unit(name)}" for name in GEOMETRY
                          if getattr(self, name) != _default(name)) or "the geometry"
        return ValueError(f"{moved}: {what} double range ({error}); allowed range: a beam and patch whose "
                          "stiffnesses E W t^3 / 12, masses and capacitance lie within (5e-324, 1.8e308)")

    def replace(self, **changes) -> "Parameters":
        """A copy with some values changed, validated anew."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """All values by name (SI), JSON-safe."""
        return dataclasses.asdict(self)


#: The beam's and the patch's values, from which the barrier's equivalents are derived.
GEOMETRY = ("E_b", "L", "t_b", "W_b", "rho_b", "x1", "E_p", "L_p", "t_p", "W_p", "rho_p", "g31", "d31", "eps33")


def _unit(name: str) -> str:
    return parameter_info()[name]["unit"]


def _default(name: str) -> float:
    return parameter_info()[name]["default"]


def parameter_info() -> dict[str, dict]:
    """Unit, description, bound and default of every parameter, by name."""
    return {
        f.name: {"unit": f.metadata["unit"], "description": f.metadata["description"],
                 "bound": f.metadata["bound"], "default": f.default}
        for f in dataclasses.fields(Parameters)
    }
