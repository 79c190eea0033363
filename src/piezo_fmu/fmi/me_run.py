"""One Model Exchange run of the damper (:mod:`piezo_fmu.fmi.me`): the model's equations on its
state, and its event update.

:class:`Equations` are the right-hand side, the event indicators and the nominal sizes of the
states, from the model (:class:`piezo_fmu.model.Damper`) of one parameter set. :class:`Run` is the
state of one run (continuous states, phase, discrete bookkeeping) with its event update, which
applies the model's switch rules and records the events in the solver's metric accumulators,
and the readings a host gets from it.
"""

from __future__ import annotations

import math
import operator
import sys
from typing import Optional

from piezo_fmu.fmi.variables import INDICATORS, STATES
from piezo_fmu.model.damper import FREE, LEFT, RIGHT, Damper
from piezo_fmu.model.dynamics import DU, DW, approach_sign
from piezo_fmu.model.rounding import EPS, MAX_SWITCHES_AT_ONE_INSTANT, NOISE_ULPS
from piezo_fmu.model.voltage import QUASI_STATIC, circuit_rate, quasi_static
from piezo_fmu.solver import EnergyLedger
from piezo_fmu.solver.metrics import MetricAccumulators

#: Indices of the continuous states (:data:`piezo_fmu.fmi.variables.STATES`).
P, DP, Q, DQ, V_LEFT, V_RIGHT, D_C, D_CEQ, W_BASE, H_LEFT, H_RIGHT, CONVERTED = range(len(STATES))
#: A deflection within this fraction of the gap of zero may be the host's error (its event location:
#: CVode's, 1e-13 s, moves a body at 1 m/s by 1e-13 m; its integration error in contact): a body
#: that far into a barrier or out of it is not switched against its relative motion, and a switch
#: puts it on the surface. Whether a body short of a barrier touches it is decided at rounding.
SURFACE = 1e-9
#: The rounding level of the indicators, relative to the sizes they are made of (the solver's).
NOISE = NOISE_ULPS * EPS
#: The value of an indicator in a phase that does not use it.
UNUSED = 1.0
#: The least rounding level of an indicator, so that none is ever shown as an exact zero.
FLOOR = sys.float_info.min


def held(value: float, level: float, sign: int) -> float:
    """An indicator's ``value``, or its rounding ``level`` with the ``sign`` of the side it is held on
    where the value is within that level of zero: the indicator then changes sign only where the
    value clearly crosses, and an event update never leaves one at zero or on the wrong side of a
    crossing that rounding alone decides (docs/fmu.md, "Event indicators")."""
    return value if abs(value) > level else math.copysign(level, sign)


def _dot(row, xs) -> float:
    return sum(map(operator.mul, row, xs))


class Equations:
    """The damper's equations on the Model Exchange state, derived once from its model: the rows of
    the phase matrices that give ``p''`` and ``q''``, the energy rates, and the circuit constants."""

    def __init__(self, damper: Damper):
        self.damper = damper
        self.params = params = damper.params
        self.rows = {side: (A[DU].tolist(), A[DW].tolist())
                     for side, A in ((side, damper.matrix(side)) for side in (FREE, RIGHT, LEFT))}
        self.rates = {side: damper.rates(side).T.tolist() for side in (FREE, RIGHT, LEFT)}
        self.circuit = params.voltage_model != QUASI_STATIC
        barrier = damper.barrier
        self.chi, self.C_p, self.R, self.k_V = barrier.chi, barrier.C_p, params.R_load, barrier.k_V

    def deviation(self, x: list, side: int, y: float, v: float) -> list:
        """The model's deviation state ``(p - y, q - y, p' - v, q' - v, 1[, V])`` of phase ``side``."""
        xs = [x[P] - y, x[Q] - y, x[DP] - v, x[DQ] - v, 1.0]
        if side != FREE and self.damper.coupled:
            xs.append(x[V_RIGHT if side == RIGHT else V_LEFT])
        return xs

    def acceleration(self, x: list, side: int, y: float, v: float) -> float:
        """``p''`` (m/s^2)."""
        return _dot(self.rows[side][0], self.deviation(x, side, y, v))

    def surface(self, x: list) -> float:
        """The rounding level (m) of a deflection, ``q - p - d/2`` or its mirror: within it, the
        impact mass touches the barrier's surface."""
        return NOISE * (abs(x[P]) + abs(x[Q]) + self.params.d / 2) + FLOOR

    def deflection_rate(self, x: list, side: int) -> float:
        """``delta' = s (q' - p')`` (m/s) of the barrier on ``side``."""
        return side * (x[DQ] - x[DP])

    def derivatives(self, x: list, side: int, y: float, v: float) -> list:
        """The time derivatives of the states (:data:`~piezo_fmu.fmi.variables.STATES`), SI."""
        xs = self.deviation(x, side, y, v)
        du_row, dw_row = self.rows[side]
        u_rate, relative_rate, force = (_dot(rate, xs) for rate in self.rates[side])
        params = self.params
        dx = [x[DP], _dot(du_row, xs), x[DQ], _dot(dw_row, xs), 0.0, 0.0, params.C * u_rate * u_rate,
              params.C_eq * relative_rate * relative_rate, -v * force, 0.0, 0.0, 0.0]
        if self.circuit:
            rate = self.deflection_rate(x, side) if side != FREE else 0.0
            v_left, v_right = x[V_LEFT], x[V_RIGHT]
            dx[V_LEFT] = circuit_rate(v_left, rate if side == LEFT else 0.0, self.chi, self.C_p, self.R)
            dx[V_RIGHT] = circuit_rate(v_right, rate if side == RIGHT else 0.0, self.chi, self.C_p, self.R)
            dx[H_LEFT], dx[H_RIGHT] = v_left * v_left / self.R, v_right * v_right / self.R
            if side != FREE:
                dx[CONVERTED] = self.chi * (v_right if side == RIGHT else v_left) * rate
        return dx

    def indicators(self, x: list, side: int, signs) -> list:
        """The event indicators (:data:`~piezo_fmu.fmi.variables.INDICATORS`), each :func:`held` within
        its rounding level: the deflections on the side of the phase (positive in contact with
        their barrier), the three rates on the sides ``signs`` (deflection rate, ``p'``, ``V'``)."""
        sides = (1 if side == RIGHT else -1, 1 if side == LEFT else -1) + tuple(signs)
        return [held(value, level, sign) for value, level, sign in zip(*self.values(x, side), sides)]

    def values(self, x: list, side: int) -> tuple:
        """The indicators' values, and the rounding level of each: :data:`NOISE` scaled by what each
        is computed from, and none but :data:`FLOOR` for ``p'``, a state that is also an output (no
        cancellation makes it, and the indicator is the output's value but for an exact zero)."""
        damper, p, q = self.damper, x[P], x[Q]
        length = self.surface(x)
        z = [damper.deflection(RIGHT, p, q), damper.deflection(LEFT, p, q), UNUSED, x[DP], UNUSED]
        levels = [length, length, 0.0, FLOOR, 0.0]
        if side != FREE:
            speed = NOISE * (abs(x[DP]) + abs(x[DQ])) + FLOOR
            rate = self.deflection_rate(x, side)
            z[2], levels[2] = rate, speed
            if self.circuit:
                voltage = x[V_RIGHT if side == RIGHT else V_LEFT]
                z[4] = circuit_rate(voltage, rate, self.chi, self.C_p, self.R)
                levels[4] = (self.chi * speed + NOISE * abs(voltage) / self.R) / self.C_p + FLOOR
        return z, levels

    def nominals(self) -> list:
        """Nominal sizes of the states: half the gap, the velocity of the main mass's free motion over
        it, the voltage that velocity drives into the load at the contact frequency, the energy of
        the main spring stretched by half the gap."""
        params = self.params
        length = params.d / 2
        speed = length * math.sqrt(params.K / params.M)
        volt = 1.0
        if self.circuit:
            volt = self.chi * speed * self.R / (1.0 + self.damper.contact_frequency * self.R * self.C_p)
        energy = 0.5 * params.K * length * length
        return [length, speed, length, speed, volt, volt] + [energy] * 6


class Run:
    """The Model Exchange state of one run: continuous states ``x`` (:data:`STATES` order), phase,
    and the discrete bookkeeping; with the event update and the readings."""

    def __init__(self, equations: Equations, t0: float, y0: float, v0: float):
        self.eq = equations
        params = equations.params
        self.t = t0
        self.x = [params.p0, params.dp0, params.q0, params.dq0] + [0.0] * 8
        self.side = FREE
        self.plastic = 0.0
        self.initial = sum(equations.damper.mechanical_energy(FREE, params.p0, params.dp0, params.q0, params.dq0, y0))
        self.acc = MetricAccumulators()
        self.peak_deflection = self.peak_voltage = 0.0
        self.rising = self._rising(y0, v0)  # a zero of p' at the start is no maximum
        self.held = [1, 1]  # the sides the indicators of delta' and V' are held on (p''s: self.rising)

    # -- the event update -------------------------------------------------------------------------

    def update(self, y: float, v: float) -> bool:
        """Apply every switch due at the present instant with the base at ``y`` (m), ``v`` (m/s),
        and record the events; True when the continuous states jumped."""
        self._record_peaks()
        jumped = False
        for _ in range(MAX_SWITCHES_AT_ONE_INSTANT + 1):
            to = self._switch_due(y, v)
            if to is None:
                break
            self._switch(to)
            jumped = True
        else:
            raise RuntimeError(f"{MAX_SWITCHES_AT_ONE_INSTANT} phase switches at t = {self.t!r} s without progress")
        jumped = self._on_own_side() or jumped
        self._record_peaks()
        rising = self._rising(y, v)
        if self.rising and not rising:  # p' fell through 0: a maximum of p
            self.acc.maximum(self.t, self.x[P])
        self.rising = rising
        self._hold(y, v)
        return jumped

    def _on_own_side(self) -> bool:
        """Put the impact mass on the phase's side of a barrier it touches without a switch (within
        :data:`SURFACE`, and at or past its surface), so that the barrier's indicator can cross again;
        True when it moved."""
        x, damper, q = self.x, self.eq.damper, self.x[Q]
        for side in (RIGHT, LEFT):
            delta = damper.deflection(side, x[P], x[Q])
            if (delta <= 0.0) if side == self.side else (self.side == FREE and delta >= 0.0):
                self._snap(side, inside=side == self.side)
        return x[Q] != q

    def _hold(self, y: float, v: float) -> None:
        """The sides the indicators of ``delta'`` and ``V'`` are held on until the next event:
        where ``delta'`` is heading (by the approach rule), and the side ``V'``'s value is on
        (unchanged while within rounding). ``p'``'s is where it is heading, ``self.rising``."""
        values, levels = self.eq.values(self.x, self.side)
        volt = self.held[1] if abs(values[4]) <= levels[4] else (1 if values[4] > 0.0 else -1)
        contact = self.side != FREE and self._approach(self.side, y, v) < 0
        self.held = [-1 if contact else 1, volt]

    @property
    def signs(self) -> list:
        """The sides the three rates' indicators are held on: ``delta'``, ``p'``, ``V'``."""
        return [self.held[0], 1 if self.rising else -1, self.held[1]]

    def indicators(self) -> list:
        """The event indicators now (:meth:`Equations.indicators`)."""
        return self.eq.indicators(self.x, self.side, self.signs)

    def _approach(self, side: int, y: float, v: float) -> int:
        """The sign of the relative velocity towards the barrier on ``side``; where it is zero to
        rounding, that of the relative acceleration without the barrier's force."""
        x = self.x
        rate = self.eq.deflection_rate(x, side)
        if abs(rate) > NOISE * (abs(x[DQ]) + abs(x[DP])):
            return 1 if rate > 0.0 else -1
        return approach_sign(self.eq.params.K, self.eq.params.C, x[P] - y, x[DP] - v, side)

    def _switch_due(self, y: float, v: float) -> Optional[int]:
        """The phase to switch to now, or None (docs/model.md sections 3.6-3.7): a barrier crossed
        beyond :data:`SURFACE` (the host's error), or reached, within the deflection's rounding or
        beyond it, with the relative motion into it (out of it, in contact). A body short of a
        barrier by more than rounding has not reached it, however fast it closes."""
        x, damper = self.x, self.eq.damper
        tol, touch = SURFACE * damper.params.d, self.eq.surface(x)
        if self.side == FREE:
            for side in (RIGHT, LEFT):
                gap = damper.deflection(side, x[P], x[Q])
                if gap > tol or (gap >= -touch and self._approach(side, y, v) > 0):
                    return side
            return None
        delta = damper.deflection(self.side, x[P], x[Q])
        if delta < -tol or (delta <= touch and self._approach(self.side, y, v) < 0):
            return FREE
        return None

    def _switch(self, to: int) -> None:
        """The momentum-exact switch rules of the model, as jumps of the state."""
        x, damper = self.x, self.eq.damper
        dp, dq = x[DP], x[DQ]
        if to != FREE:
            x[DQ], loss = damper.capture(dp, dq)
            self.acc.impact_started()
            self.side = to
            self._snap(to, inside=True)
            self.peak_deflection = 0.0
            self.peak_voltage = abs(self._voltage(to))
        else:
            side = self.side
            x[DP], loss = damper.release(dp, dq)
            if self.eq.circuit:
                voltage = max(self.peak_voltage, abs(self._voltage(side)))  # ends included
            else:
                voltage = quasi_static(self.eq.k_V, self.peak_deflection)
            self.acc.impact_ended(voltage)
            if dp > 0.0 >= x[DP]:  # p' jumps from rising to falling: a corner maximum of p
                self.acc.maximum(self.t, x[P])
                self.rising = False
            self.side = FREE
            self._snap(side, inside=False)
        self.plastic += loss

    def _snap(self, side: int, inside: bool) -> None:
        """Put the impact mass on the surface of the barrier on ``side``, one rounding inside it
        (``inside``) or outside, if the event left it within :data:`SURFACE` of it."""
        x, damper = self.x, self.eq.damper
        p, d = x[P], damper.params.d
        if abs(damper.deflection(side, p, x[Q])) > SURFACE * d:
            return
        q = p + side * (d / 2)
        towards = side * math.inf if inside else -side * math.inf
        for _ in range(64):
            delta = damper.deflection(side, p, q)
            if (delta > 0.0) if inside else (delta < 0.0):
                break
            q = math.nextafter(q, towards)
        x[Q] = q

    def _record_peaks(self) -> None:
        """The open contact's largest deflection and ``|V|`` so far: its events are updates."""
        if self.side != FREE:
            x = self.x
            self.peak_deflection = max(self.peak_deflection, self.eq.damper.deflection(self.side, x[P], x[Q]))
            if self.eq.circuit:
                self.peak_voltage = max(self.peak_voltage, abs(self._voltage(self.side)))

    def _rising(self, y: float, v: float) -> bool:
        dp = self.x[DP]
        if dp != 0.0:
            return dp > 0.0
        return self.eq.acceleration(self.x, self.side, y, v) > 0.0

    def _voltage(self, side: int) -> float:
        return self.x[V_RIGHT if side == RIGHT else V_LEFT]

    # -- what a host reads ------------------------------------------------------------------------

    def readings(self, y: float, v: float) -> tuple:
        """The readings of :data:`piezo_fmu.solver.READINGS`, in its order, at the present state."""
        x, eq, side = self.x, self.eq, self.side
        damper, params = eq.damper, eq.params
        p, dp, q, dq = x[P], x[DP], x[Q], x[DQ]
        deflection = max(0.0, damper.deflection(side, p, q)) if side != FREE else 0.0
        left, right = (deflection, 0.0) if side == LEFT else (0.0, deflection)
        kinetic, potential_K, potential_Keq = damper.mechanical_energy(side, p, dp, q, dq, y)
        flows = (x[D_C], x[D_CEQ], self.plastic, x[W_BASE], self.initial)
        if eq.circuit:
            v_left, v_right = x[V_LEFT], x[V_RIGHT]
            power_left, power_right = v_left * v_left / eq.R, v_right * v_right / eq.R
            energy = EnergyLedger(kinetic, potential_K, potential_Keq, *flows,
                                  electrical=0.5 * eq.C_p * (v_left * v_left + v_right * v_right),
                                  harvested_left=x[H_LEFT], harvested_right=x[H_RIGHT], converted=x[CONVERTED],
                                  electrical_work=x[CONVERTED] if damper.coupled else 0.0)
        else:
            v_left, v_right = quasi_static(eq.k_V, left), quasi_static(eq.k_V, right)
            power_left = power_right = 0.0
            energy = EnergyLedger(kinetic, potential_K, potential_Keq, *flows)
        metrics = self.acc.metrics(params.R_load)
        return (p, dp, q, dq, left, right, v_left, v_right, params.K * (p - y) + params.C * (dp - v),
                metrics.impact_count, metrics.last_impact_voltage, metrics.V_rms, metrics.P_ave, metrics.DI,
                energy.dissipated, energy.balance_error, energy.harvested, power_left, power_right,
                energy.harvested_left, energy.harvested_right, metrics.DI_ls)

    def locals(self, y: float, v: float) -> dict:
        """The Model Exchange locals (:data:`~piezo_fmu.fmi.variables.MODEL_EXCHANGE`) by name."""
        values = dict(zip(STATES, self.x))
        values.update(zip((f"der({name})" for name in STATES), self.eq.derivatives(self.x, self.side, y, v)))
        values.update(zip(INDICATORS, self.indicators()))
        values["contact_phase"] = self.side
        return values

    # -- saving the state -------------------------------------------------------------------------

    def snapshot(self) -> dict:
        """The whole state, JSON-safe."""
        return {"t": self.t, "x": list(self.x), "side": self.side, "plastic": self.plastic, "initial": self.initial,
                "acc": self.acc.to_dict(), "peak_deflection": self.peak_deflection,
                "peak_voltage": self.peak_voltage, "rising": self.rising, "held": list(self.held)}

    def restore(self, data: dict) -> None:
        self.t, self.x, self.side = float(data["t"]), [float(value) for value in data["x"]], int(data["side"])
        self.plastic, self.initial = float(data["plastic"]), float(data["initial"])
        self.acc = MetricAccumulators.from_dict(data["acc"])
        self.peak_deflection, self.peak_voltage = float(data["peak_deflection"]), float(data["peak_voltage"])
        self.rising = bool(data["rising"])
        # A state saved before the indicators were held (0.2.0 development) has no sides: those of a start.
        self.held = [int(sign) for sign in data.get("held", (1, 1))]

    @classmethod
    def of_core(cls, sim) -> "Run":
        """The Model Exchange state of the co-simulation core ``sim`` now (its locals for a host
        that reads them in co-simulation)."""
        run = cls(Equations(sim.damper), sim.t, sim.state.y, sim.state.v)
        state, energy = sim.state, sim.energy
        run.x = [state.p, state.dp, state.q, state.dq,
                 sim.voltage(LEFT) if run.eq.circuit else 0.0, sim.voltage(RIGHT) if run.eq.circuit else 0.0,
                 energy.dissipated_C, energy.dissipated_Ceq, energy.work_base, energy.harvested_left,
                 energy.harvested_right, energy.converted]
        run.side = state.side
        return run
