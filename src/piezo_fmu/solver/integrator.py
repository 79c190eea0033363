"""The advance loop of the exact event-driven integration (docs/model.md sections 1-6).

The motion alternates between two linear phases of the model (:mod:`piezo_fmu.model`): free
flight, and contact with one barrier. Each is propagated exactly (``propagation.py``), a bracket
at a time; phase switches, the deflection peaks that give the impact voltages, and the maxima of
``p`` that give the damping inclination are located as roots on the exact trajectory
(``brackets.py``, ``roots.py``); the switches apply the model's momentum-exact rules. Nothing is
stepped with a fixed step.

The patch voltage follows ``params.voltage_model`` (docs/model.md section 5): 0, the paper's
quasi-static ``V = k_V delta`` (no circuit state at all); 1, the patch capacitance and load as a
circuit driven one way by the barrier; 2, the same circuit acting back on the barrier in contact.
Under 1 and 2 each barrier has its own voltage, exact in closed form between contacts and on
every contact bracket (``circuit.py``); under 2 it is also a column of the contact state.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..model.damper import Damper
from ..model.dynamics import FREE, LEFT, RIGHT, U, mirror_signs
from ..model.parameters import Parameters
from ..model.rounding import MAX_SWITCHES_AT_ONE_INSTANT, ZERO
from ..model.voltage import quasi_static
from .brackets import DEFER_MARGIN, MAXIMUM, PEAK, VOLTAGE_PEAK, Bracket, BracketMaps, BracketOpener, StateOverflow
from .circuit import CircuitState
from .ledger import Ledger
from .metrics import MetricAccumulators, Metrics
from .propagation import MIN_BRACKET, POWER_EXPONENTS, POWERS_AT_END, STATE_TERMS, LinearPhase
from .records import Impact
from .roots import horner



class Integrator:
    """The damper from ``t0`` on, advanced by :meth:`advance` with any chop of time: the state,
    the open bracket and the bookkeeping of events, energy and metrics. It takes the arguments
    of :class:`~piezo_fmu.solver.simulator.Simulator`, which adds the readings."""

    def __init__(self, params: Parameters, y0: float = 0.0, v0: float = 0.0, t0: float = 0.0,
                 log_limit: int | None = None):
        _check_finite(y0=y0, v0=v0, t0=t0)
        self.params = params
        self.damper = damper = Damper.of(params)
        self.barrier = damper.barrier
        self._free = LinearPhase(damper.free, damper.free_rho)
        right = LinearPhase(damper.contact)
        n = damper.contact_size
        # The left barrier is the right one seen with the signs of the constant (and the voltage)
        # turned over: exact sign changes, not a second series.
        self._contact = {RIGHT: right, LEFT: right.mirrored(mirror_signs(n))}
        _check_time_scales(params, self._free, right)
        maps = {FREE: BracketMaps(self._free, damper.functionals(FREE), damper.rates(FREE)),
                RIGHT: BracketMaps(right, damper.functionals(RIGHT), damper.rates(RIGHT))}
        maps[LEFT] = maps[RIGHT].mirrored(self._contact[LEFT], mirror_signs(n))
        self._opener = BracketOpener(maps, ZERO * params.d, params.K, params.C)
        #: The two patch circuits (voltage_model 1 and 2); None under the quasi-static model 0.
        self._circuit = (CircuitState(self.barrier.chi, self.barrier.C_p, params.R_load, damper.coupled, t0)
                         if params.voltage_model else None)
        self.t = float(t0)
        self._p, self._dp, self._q, self._dq = params.p0, params.dp0, params.q0, params.dq0
        self._side = FREE
        self._y, self._v = float(y0), float(v0)
        self._bracket: Bracket | None = None
        self._ledger = Ledger(params.C, params.C_eq)
        try:
            kinetic, potential_K, potential_Keq = damper.mechanical_energy(FREE, self._p, self._dp, self._q, self._dq,
                                                                           self._y)
            self._ledger.initial = kinetic + potential_K + potential_Keq
        except OverflowError:  # float ** overflows with an exception, * with inf
            self._ledger.initial = math.inf
        if not math.isfinite(self._ledger.initial):
            big = {name: value for name, value in (("p0", params.p0), ("q0", params.q0), ("dp0", params.dp0),
                                                   ("dq0", params.dq0), ("y0", y0)) if abs(value) > 1e100}
            raise ValueError(f"{', '.join(f'{k} = {v!r}' for k, v in big.items()) or 'the start'}: the initial energy "
                             "overflows double precision; allowed range: values whose energy stays finite "
                             "(|displacements| and |velocities| well below 1e150)")
        self._acc = MetricAccumulators()
        self._metrics: Metrics | None = None
        self._open: Impact | None = None
        self._impacts: deque[Impact] = deque(maxlen=log_limit)
        self._maxima: deque[tuple[float, float]] = deque(maxlen=log_limit)
        #: Brackets opened so far: the unit of work of the integrator.
        self.brackets_opened = 0

    # ------------------------------------------------------------------ stepping
    def advance(self, t_end: float, y: float, v: float) -> None:
        """Integrate to ``t_end`` (s) with the base ``y + v (t - t_now)`` (m), velocity ``v`` (m/s).

        Raises ``ValueError`` for a non-finite argument or ``t_end`` not after the present time.
        A call that continues the previous one's base motion (same ``v``, and ``y`` where the
        previous call left the base) goes on with the same brackets, so how time is chopped
        changes no event and no switch.
        """
        if not math.isfinite(t_end + y + v):
            _check_finite(t_end=t_end, y=y, v=v)
        if not t_end > self.t:
            raise ValueError(f"t_end = {t_end!r} s must be after the present time t = {self.t!r} s")
        if y != self._y or v != self._v:
            self._close_bracket()
            if y != self._y:
                # The host moved the base end of the spring: that work enters the ledger.
                try:
                    jump = 0.5 * self.params.K * ((self._p - y) ** 2 - (self._p - self._y) ** 2)
                except OverflowError:  # float ** overflows with an exception, * with inf
                    jump = math.inf
                if not math.isfinite(jump):
                    raise ValueError(f"y = {y!r} m: the base displacement puts an energy beyond double precision in the "
                                     "spring; allowed range: |y - p| well below 1e150 m")
                self._ledger.work_base += jump
            self._y, self._v = float(y), float(v)
        instant_switches = 0
        while True:
            if self._bracket is None:
                self._bracket = self._open_bracket()
                self.brackets_opened += 1
            br = self._bracket
            s_stop = (t_end - br.t_start) / br.tau
            if s_stop > 1.0:
                s_stop = 1.0
            if br.deferred is not None and s_stop + DEFER_MARGIN > br.deferred.clear:
                br.located_to(s_stop)  # the searches put off, run if this move may meet a root
            s_to = s_stop if s_stop < br.s_switch else br.s_switch
            while br.events and br.events[0][0] <= s_to:
                self._non_terminal_event(br, *br.events.pop(0))
            if br.s_switch <= s_stop:
                self._move_to(br, br.s_switch, br.t_start + br.s_switch * br.tau)
                instant_switches = instant_switches + 1 if br.s_switch == 0.0 else 0
                if instant_switches > MAX_SWITCHES_AT_ONE_INSTANT:
                    raise RuntimeError(f"{instant_switches} phase switches at t = {self.t!r} s without progress")
                self._close_bracket()
                self._switch(br.switch_to)
                continue
            if s_stop == 1.0:
                self._move_to(br, 1.0, br.t_start + br.tau)
                self._close_bracket()
                if self.t < t_end:
                    continue
            else:
                self._move_to(br, s_stop, t_end)
            break
        self.t = t_end

    def _move_to(self, br: Bracket, s: float, t: float) -> None:
        """Set the state to the bracket's trajectory at normalised time ``s`` (time ``t``)."""
        br.powers = pw = POWERS_AT_END if s == 1.0 else s ** POWER_EXPONENTS  # propagation.powers, inlined
        u, w, du, dw = pw[:STATE_TERMS].dot(br.c).tolist()[:4]  # ndarray.dot: np.dot without its dispatch
        base = br.base + br.v * s * br.tau
        self.t = t
        self._p, self._q = u + base, w + base
        self._dp, self._dq = du + br.v, dw + br.v
        self._y = base
        br.s = s

    def _open_bracket(self) -> Bracket:
        """A new bracket from the present state, with every event on it located."""
        side, y, v = self._side, self._y, self._v
        xs = [self._p - y, self._q - y, self._dp - v, self._dq - v, 1.0]
        circuit = self._circuit
        if side != FREE and self.damper.coupled:
            xs.append(circuit.V[(side + 1) // 2])
        try:
            br = self._opener.open(side, xs, self.t, y, v)
        except StateOverflow:
            raise ValueError(f"y = {y!r} m, v = {v!r} m/s at t = {self.t!r} s: the state (p = {self._p!r} m, "
                             f"q = {self._q!r} m, p' = {self._dp!r} m/s, q' = {self._dq!r} m/s) overflows double "
                             "precision on the next bracket; allowed range: base and state well below 1e150") from None
        if side != FREE and circuit is not None:
            piece = circuit.open(br.c, br.tau, side)
            if br.s_switch > 0.0:  # the peaks of |V| on the way, unless the bracket ends at once
                br.events += [(s, VOLTAGE_PEAK) for s in piece.peaks(min(br.s_switch, 1.0))]
                br.events.sort()
        return br

    def _non_terminal_event(self, br: Bracket, s: float, kind: int) -> None:
        if kind == MAXIMUM:
            p = horner(br.c[:, U].tolist(), s) + br.base + br.v * s * br.tau
            self._record_maximum(br.t_start + s * br.tau, p)
        elif kind == PEAK:
            self._open.max_deflection = max(self._open.max_deflection, horner(br.delta.tolist(), s))
        else:
            self._circuit.peak_at(s)

    def _close_bracket(self) -> None:
        """Book the ledger (and the circuit) of the present bracket up to where the state stands,
        and drop it.

        The ledger of an open bracket is read from its primitives at the present position, and
        booked only when the bracket closes; so the ledger, like the state, does not depend on
        how the calls chopped the bracket.
        """
        br = self._bracket
        if br is None:
            return
        self._ledger.close(br)
        self._bracket = None
        if self._circuit is not None:
            self._circuit.close(br.s, br.powers, self.t)

    def _record_maximum(self, t: float, p: float) -> None:
        self._metrics = None
        self._maxima.append((t, p))
        self._acc.maximum(t, p)

    def _switch(self, to: int) -> None:
        """Apply the momentum-exact switch rules of the model at the present time."""
        self._metrics = None
        dp, dq = self._dp, self._dq
        if to != FREE:
            dq_after, loss = self.damper.capture(dp, dq)
            self._open = Impact(time=self.t, side=to, rel_velocity=dq - dp, dp_before=dp, dq_before=dq,
                                dp_after=dp, dq_after=dq_after, capture_loss=loss)
            self._acc.impact_started()
            self._dq = dq_after
            if self._circuit is not None:
                # The barrier's voltage decayed since it was booked; the contact starts from it.
                self._circuit.contact(to, self.t)
        else:
            dp_after, loss = self.damper.release(dp, dq)
            impact = self._open
            impact.duration = self.t - impact.time
            if self._circuit is not None:
                impact.voltage = self._circuit.peak  # peak |V| over the contact, ends included
            else:
                impact.voltage = quasi_static(self.barrier.k_V, impact.max_deflection)
            impact.dp_sep_before, impact.dq_sep_before = dp, dq
            impact.dp_sep_after, impact.dq_sep_after = dp_after, dq
            impact.release_loss = loss
            self._impacts.append(impact)
            self._open = None
            self._acc.impact_ended(impact.voltage)
            self._dp = dp_after
            if dp > 0.0 >= dp_after:
                # p' jumps from rising to falling: a (corner) maximum of p.
                self._record_maximum(self.t, self._p)
        self._ledger.plastic += loss
        self._side = to


def _check_time_scales(params: Parameters, free: LinearPhase, contact: LinearPhase) -> None:
    """Refuse a damper whose fastest mode is beyond what the integrator can represent."""
    for name, phase in (("free flight", free), ("contact", contact)):
        if not (phase.h >= MIN_BRACKET and np.isfinite(phase._terms).all()):
            raise ValueError(
                f"M = {params.M!r} kg, K = {params.K!r} N/m, C = {params.C!r} N.s/m, m = {params.m!r} kg, "
                f"C_eq = {params.C_eq!r} N.s/m (and the barrier's K_eq, M_eq): the {name} phase turns by 2 rad in "
                f"{phase.h:.3g} s; allowed range: at least {MIN_BRACKET:g} s (a stiffness to mass or damping to "
                "mass ratio below about 1e18)")


def _check_finite(**values: float) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name} = {value!r} is not finite; allowed range (-inf, inf)")
