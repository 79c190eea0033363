"""PrimaryStructure: an SDOF primary structure (a building floor or a machine frame) on moving
ground, as an FMI 2.0 co-simulation FMU built with pythonfmu (``hosts/build_structure.py``).

Absolute coordinates (an inertial frame): the floor mass ``M_s`` at displacement ``X`` is tied to
the ground ``u_g`` by the spring ``K_s`` and the damper ``C_s``, and carries the force ``F`` that
a device mounted on it exerts on it (input ``damper_force``; the damper FMU's ``base_force``):

    M_s X'' = -K_s (X - u_g) - C_s (X' - v_g) + F.

The ground motion is the deterministic synthetic record of ``primary_structure_ground``
(``u_g``, ``v_g`` and the acceleration ``a_g`` in closed form), scaled to ``pga``.

The FMU keeps its own clock on whole nanoseconds (``on_nanosecond_grid``), so that its result
does not depend on how a master rounds its communication points. Within a communication step
the input ``F`` is held (the value set before ``fmi2DoStep``) and
the motion is integrated with the classical Runge-Kutta method on equal sub-steps of at most
``max_internal_step``, together with the energy integrals of the ledger:

- ``work_ground = -int (K_s (X - u_g) + C_s (X' - v_g)) v_g dt``, the work the ground does on
  the structure through its spring and damper;
- ``work_device = int F X' dt``, the work the device does on the structure;
- ``energy_dissipated = int C_s (X' - v_g)^2 dt``;
- ``energy = M_s X'^2 / 2 + K_s (X - u_g)^2 / 2``;
- ``energy_balance_error = energy - (energy(0) + work_ground + work_device - energy_dissipated)``,
  the integrator's own error (it is not zero to rounding: Runge-Kutta's truncation shows).

Errors do not escape as exceptions: a non-finite input or a step that does not start at the
FMU's time is logged and the step returns ``fmi2Discard``.
"""

from __future__ import annotations

import math

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from primary_structure_ground import GroundMotion

PARAMETERS = (
    # name, start, description
    ("M_s", 20.0, "Mass of the floor (kg)"),
    ("K_s", 20000.0, "Stiffness of the floor's support (N/m)"),
    ("C_s", 25.0, "Damping of the floor's support (N.s/m)"),
    ("pga", 1.0, "Peak ground acceleration of the record (m/s2)"),
    ("max_internal_step", 1e-4, "Longest Runge-Kutta sub-step within a communication step (s)"),
)

OUTPUTS = (
    ("displacement", "Absolute displacement X of the floor (m)"),
    ("velocity", "Absolute velocity X' of the floor (m/s)"),
    ("relative_displacement", "Drift X - u_g of the floor against the ground (m)"),
    ("ground_displacement", "Ground displacement u_g (m)"),
    ("ground_velocity", "Ground velocity v_g (m/s)"),
    ("ground_acceleration", "Ground acceleration a_g, the record (m/s2)"),
    ("energy", "Kinetic plus elastic energy of the floor (J)"),
    ("work_ground", "Work done by the ground on the floor since the start (J)"),
    ("work_device", "Work done by the device (input damper_force) on the floor since the start (J)"),
    ("energy_dissipated", "Energy dissipated in C_s since the start (J)"),
    ("energy_balance_error", "energy - (initial energy + work_ground + work_device - energy_dissipated) (J)"),
)


def on_nanosecond_grid(t: float) -> float:
    """``t`` moved to the nearest whole nanosecond when it lies within ``1e-12 * max(1, |t|)`` s
    of it, else ``t``.

    Masters count time differently (OSP libcosim in integer nanoseconds, ecos by adding the step
    at every step, fmpy as ``start + k * step``): their communication points for the same grid
    differ in the last bits, by up to ~1e-13 s after a few thousand steps. Taking the end of each
    step to the nanosecond makes this FMU's own clock, and so its result, the same under all
    of them.
    """
    snapped = round(t * 1e9) / 1e9
    return snapped if abs(snapped - t) <= 1e-12 * max(1.0, abs(t)) else t


class PrimaryStructure(Fmi2Slave):
    """SDOF floor on moving ground (synthetic record), with a device force input."""

    author = "piezo-fmu"
    description = "SDOF primary structure on a synthetic ground-motion record, with a device force input"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=5.0, step_size=1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for name, start, _ in PARAMETERS:
            setattr(self, name, start)
        self.damper_force = 0.0
        for name, _ in OUTPUTS:
            setattr(self, name, 0.0)
        self._ground = None
        self._state = None  # (t, X, V, work_ground, dissipated, work_device)
        self._energy0 = 0.0
        for name, _, description in PARAMETERS:
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed, initial=Fmi2Initial.exact,
                                        description=description))
        self.register_variable(Real("damper_force", causality=Fmi2Causality.input,
                                    variability=Fmi2Variability.continuous,
                                    description="Force the mounted device exerts on the floor, along +x (N); "
                                                "held over each communication step"))
        for name, description in OUTPUTS:
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous, description=description))

    # -- FMI ----------------------------------------------------------------------------------

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._start_time = float(start_time)

    def exit_initialization_mode(self):
        self._ground = GroundMotion(self.pga)
        t = getattr(self, "_start_time", 0.0)
        u, v, _ = self._ground(t)
        self._state = (t, u, v, 0.0, 0.0, 0.0)  # at rest on the ground
        self._publish()
        self._energy0 = self.energy
        self._publish()

    def do_step(self, current_time, step_size):
        if self._state is None:
            self.log("the FMU was not initialized", Fmi2Status.error)
            return False
        t0 = self._state[0]
        # twice the grid's window: a start moved onto the grid, plus the host's own rounding of it
        if not abs(current_time - t0) <= 2e-12 * max(1.0, abs(t0)):
            self.log(f"the step starts at t = {current_time!r} s but the FMU is at t = {t0!r} s", Fmi2Status.error)
            return False
        force = float(self.damper_force)
        if not (math.isfinite(force) and step_size > 0.0 and math.isfinite(step_size)):
            self.log(f"rejected step: damper_force = {force!r}, step = {step_size!r}", Fmi2Status.error)
            return False
        t_end = on_nanosecond_grid(current_time + step_size)
        if not t_end > t0:
            t_end = current_time + step_size
        n = max(1, math.ceil((t_end - t0) / self.max_internal_step - 1e-9))
        h = (t_end - t0) / n
        state = self._state[1:]
        t = t0
        for i in range(n):
            state = self._rk4(t, state, h, force)
            t = t0 + (i + 1) * h
        self._state = (t_end,) + tuple(state)
        self._publish()
        return True

    # -- the model ------------------------------------------------------------------------------

    def _rates(self, t, state, force, ground):
        x, v = state[0], state[1]
        u_g, v_g, _ = ground
        spring_damper = self.K_s * (x - u_g) + self.C_s * (v - v_g)
        return (v, (force - spring_damper) / self.M_s, -spring_damper * v_g,
                self.C_s * (v - v_g) ** 2, force * v)

    def _rk4(self, t, state, h, force):
        g0, g_half, g1 = self._ground(t), self._ground(t + 0.5 * h), self._ground(t + h)
        k1 = self._rates(t, state, force, g0)
        s2 = tuple(s + 0.5 * h * k for s, k in zip(state, k1))
        k2 = self._rates(t + 0.5 * h, s2, force, g_half)
        s3 = tuple(s + 0.5 * h * k for s, k in zip(state, k2))
        k3 = self._rates(t + 0.5 * h, s3, force, g_half)
        s4 = tuple(s + h * k for s, k in zip(state, k3))
        k4 = self._rates(t + h, s4, force, g1)
        return tuple(s + h / 6.0 * (a + 2.0 * b + 2.0 * c + d) for s, a, b, c, d in zip(state, k1, k2, k3, k4))

    def _publish(self):
        t, x, v, work_ground, dissipated, work_device = self._state
        u_g, v_g, a_g = self._ground(t)
        self.displacement, self.velocity = x, v
        self.relative_displacement = x - u_g
        self.ground_displacement, self.ground_velocity, self.ground_acceleration = u_g, v_g, a_g
        self.energy = 0.5 * self.M_s * v * v + 0.5 * self.K_s * (x - u_g) ** 2
        self.work_ground, self.energy_dissipated, self.work_device = work_ground, dissipated, work_device
        self.energy_balance_error = self.energy - (self._energy0 + work_ground + work_device - dissipated)
