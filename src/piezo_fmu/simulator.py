"""Event-driven, exact simulation of the piezo-impact damper (MODEL.md sections 1-6).

The motion alternates between two linear phases: free flight (a damped oscillator driven by
the base, and a free particle) and contact with one barrier (the 2-DOF system of MODEL.md
section 3). Each is propagated exactly (``propagation.py``); phase switches, the deflection
peaks that give the impact voltages, and the maxima of ``p`` that give the damping
inclination are located as roots on the exact trajectory (``roots.py``). Nothing is stepped
with a fixed step.

The patch voltage follows ``params.voltage_model`` (MODEL.md section 5): 0, the paper's
quasi-static ``V = k_V delta`` (no circuit state at all); 1, the patch capacitance and load as a
circuit driven one way by the barrier; 2, the same circuit acting back on the barrier in contact.
Under 1 and 2 each barrier has its own voltage, exact in closed form between contacts and on
every contact bracket (``circuit.py``); under 2 it is also a column of the contact state.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import numpy as np

from .barrier import derive_barrier
from .circuit import Piece, decay, driven
from .metrics import MetricAccumulators, Metrics
from .parameters import COUPLED, Parameters
from .propagation import (MIN_BRACKET, POWERS_AT_START, PRIMITIVE_TERMS, STATE_TERMS, LinearPhase, evaluate, powers,
                          primitive, primitive_of_square)
from .roots import bernstein, crossings, may_cross

FREE = 0
RIGHT = +1
LEFT = -1
#: Switches allowed at one instant before the run is declared degenerate.
MAX_SWITCHES_AT_ONE_INSTANT = 8
#: Relative size, against the gap, under which an event function at a bracket start is zero.
_ZERO = 1e-13
#: Rounding level of an event function, in ulp of the largest state term it is made of.
_NOISE_ULPS = 64
EPS = float(np.finfo(float).eps)

# Columns of the deviation state x = (u, w, u', w', 1), with u = p - y(t), w = q - y(t); in
# contact under voltage_model = 2, the patch voltage V of the barrier in contact follows.
U, W, DU, DW, ONE, VOLT = range(6)


class State(NamedTuple):
    """The state at time ``t`` (s): absolute displacements (m) and velocities (m/s).

    ``side`` is 0 in free flight, +1 in contact with the right barrier (``q - p = +d/2`` side),
    -1 with the left one. ``y`` (m) and ``v`` (m/s) are the base displacement and velocity.
    """

    t: float
    p: float
    dp: float
    q: float
    dq: float
    side: int
    y: float
    v: float


@dataclass
class Impact:
    """One contact with a barrier.

    ``time`` (s) is the onset, ``side`` +1 (right) or -1 (left), ``rel_velocity`` (m/s) the
    relative velocity ``q' - p'`` at onset before the tip mass is captured,
    ``max_deflection`` (m) the peak barrier tip deflection, ``voltage`` (V) the impact voltage
    ``V_i``: ``k_V max_deflection`` under ``voltage_model = 0``, the peak ``|V|`` across the load
    during the contact (ends included) under 1 and 2 (NaN while the contact lasts);
    ``duration`` (s) the contact time (NaN while the contact lasts).
    ``dp_*``/``dq_*`` (m/s) are the absolute velocities just before and after the onset and the
    separation switches, and ``capture_loss``/``release_loss`` (J) the plastic losses there.
    """

    time: float
    side: int
    rel_velocity: float
    dp_before: float
    dq_before: float
    dp_after: float
    dq_after: float
    capture_loss: float
    max_deflection: float = 0.0
    voltage: float = math.nan
    duration: float = math.nan
    dp_sep_before: float = math.nan
    dq_sep_before: float = math.nan
    dp_sep_after: float = math.nan
    dq_sep_after: float = math.nan
    release_loss: float = math.nan


class EnergyLedger(NamedTuple):
    """Energy bookkeeping since the start, J.

    ``kinetic``, ``potential_K`` and ``potential_Keq`` are the present energies; the others
    accumulate: viscous dissipation in ``C`` and ``C_eq``, ``plastic`` losses of tip-mass
    capture and release, and ``work_base``, the work the base did on the device (including
    jumps of a base displacement set by the host). ``initial`` is the energy at the start.

    The circuit (``voltage_model`` 1 and 2; all zero under 0, which has no circuit):
    ``electrical`` is the energy now stored in the two patch capacitances, ``0.5 C_p V^2``;
    ``harvested_left``/``harvested_right`` accumulate ``int V^2 / R dt`` of each barrier;
    ``converted`` accumulates ``int chi V delta' dt``, the power the barrier in contact feeds the
    circuit; ``electrical_work`` is the part of it the mechanics paid: ``converted`` under the
    coupled model 2, 0 under the one-way model 1 (which supplies it without acting back).
    """

    kinetic: float
    potential_K: float
    potential_Keq: float
    dissipated_C: float
    dissipated_Ceq: float
    plastic: float
    work_base: float
    initial: float
    electrical: float = 0.0
    harvested_left: float = 0.0
    harvested_right: float = 0.0
    converted: float = 0.0
    electrical_work: float = 0.0

    @property
    def total(self) -> float:
        """Present mechanical energy, J."""
        return self.kinetic + self.potential_K + self.potential_Keq

    @property
    def harvested(self) -> float:
        """Energy harvested in the loads of both barriers so far, J."""
        return self.harvested_left + self.harvested_right

    @property
    def electrical_balance_error(self) -> float:
        """``electrical + harvested - converted``, J: the circuit's own balance, zero for exact bookkeeping."""
        return self.electrical + self.harvested - self.converted

    @property
    def dissipated(self) -> float:
        """All energy dissipated so far, J."""
        return self.dissipated_C + self.dissipated_Ceq + self.plastic

    @property
    def balance_error(self) -> float:
        """``total - (initial + work_base - dissipated - electrical_work)``, J: zero for exact bookkeeping."""
        return self.total - (self.initial + self.work_base - self.dissipated - self.electrical_work)


_MAXIMUM, _PEAK, _VOLTAGE_PEAK = 0, 1, 2


@dataclass
class _Bracket:
    """One bracket of the present phase: its exact trajectory and its located events.

    ``c`` holds the Taylor coefficients of the deviation state over ``[t_start, t_start + tau]``
    (normalised time ``s`` in [0, 1]); ``base`` (m) and ``v`` (m/s) are the base there. The
    phase switches at ``s_switch`` (inf: not in this bracket) to side ``switch_to``; ``events``
    are the non-terminal events ``(s, kind)`` still ahead; ``s`` is where the state stands.
    ``ledger`` holds the primitives of the ledger's rates over the bracket.
    """

    c: np.ndarray
    t_start: float
    tau: float
    base: float
    v: float
    s: float = 0.0
    s_switch: float = math.inf
    switch_to: int = FREE
    events: list = field(default_factory=list)
    delta: np.ndarray | None = None
    ledger: np.ndarray | None = None
    #: ``s**k`` at the present position, k < PRIMITIVE_TERMS: serves the state and the ledger.
    powers: np.ndarray = field(default_factory=lambda: POWERS_AT_START)

    def to_dict(self) -> dict:
        data = asdict(self)
        for name in ("c", "delta", "ledger", "powers"):
            value = getattr(self, name)
            data[name] = None if value is None else value.tolist()
        data["events"] = [list(e) for e in self.events]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "_Bracket":
        data = dict(data)
        for name in ("c", "delta", "ledger", "powers"):
            if data[name] is not None:
                data[name] = np.array(data[name], dtype=float)
        if data["delta"] is not None:
            # Made as a column of the (terms, 3) matrix of event functions: restored with the same
            # strides, so that the dot products that evaluate it round alike (bit-identical peaks).
            columns = np.zeros((data["delta"].size, 3))
            columns[:, 0] = data["delta"]
            data["delta"] = columns[:, 0]
        data["events"] = [(float(s), int(k)) for s, k in data["events"]]
        return cls(**data)


@dataclass
class _Accounts:
    dissipated_C: float = 0.0
    dissipated_Ceq: float = 0.0
    plastic: float = 0.0
    work_base: float = 0.0
    initial: float = 0.0


class Simulator:
    """The damper from ``t0`` on, advanced by :meth:`advance` with any chop of time.

    Parameters
    ----------
    params : Parameters
        The damper, SI.
    y0, v0 : float
        Base displacement (m) and velocity (m/s) at ``t0``.
    t0 : float
        Start time, s.
    log_limit : int or None
        Most impacts and maxima kept in :attr:`impacts` and :attr:`maxima` (the oldest are
        dropped); the metrics never depend on it. None keeps all.
    """

    def __init__(self, params: Parameters, y0: float = 0.0, v0: float = 0.0, t0: float = 0.0,
                 log_limit: int | None = None):
        _check_finite(y0=y0, v0=v0, t0=t0)
        self.params = params
        self.barrier = derive_barrier(params)
        M, m, K, C = params.M, params.m, params.K, params.C
        M_eq, K_eq, C_eq = self.barrier.M_eq, self.barrier.K_eq, params.C_eq
        self._M_contact = M - M_eq
        self._m_contact = m + M_eq
        self._free = LinearPhase(_free_matrix(M, K, C))
        #: The voltage model: 0 quasi-static (no circuit state), 1 circuit one-way, 2 coupled.
        self._vm = params.voltage_model
        #: The voltage of the barrier in contact on the open bracket (voltage_model 1 and 2).
        self._piece: Piece | None = None
        coupling = None
        if self._vm == COUPLED:
            coupling = (self.barrier.chi, self.barrier.C_p, params.R_load)
        self._contact = {side: LinearPhase(_contact_matrix(self._M_contact, self._m_contact, K, C, K_eq, C_eq, params.d, side,
                                                           coupling))
                         for side in (RIGHT, LEFT)}
        _check_time_scales(params, self._free, self._contact[RIGHT])
        self._zero = _ZERO * params.d
        self._functionals = {side: _event_functionals(side, params.d, self._contact[RIGHT].A.shape[0] if side else 5)
                             for side in (FREE, RIGHT, LEFT)}
        self._magnitudes: dict[int, np.ndarray] = {}  # |functionals|, kept by _event_maps
        if self._vm:
            self._RC = params.R_load * self.barrier.C_p
            # Per barrier (index (side + 1) // 2: left 0, right 1): the voltage booked at time
            # _circuit_t and the energy harvested up to then; the peak |V| of the open contact,
            # the converted energy booked, and the voltage on the open contact bracket.
            self._circuit_V = [0.0, 0.0]
            self._circuit_t = [float(t0), float(t0)]
            self._circuit_harvested = [0.0, 0.0]
            self._circuit_converted = 0.0
            self._circuit_peak = 0.0

        self.t = float(t0)
        self._p, self._dp, self._q, self._dq = params.p0, params.dp0, params.q0, params.dq0
        self._side = FREE
        self._y, self._v = float(y0), float(v0)
        self._bracket: _Bracket | None = None
        self._accounts = _Accounts()
        try:
            self._accounts.initial = self.energy.total
        except OverflowError:  # float ** overflows with an exception, * with inf
            self._accounts.initial = math.inf
        if not math.isfinite(self._accounts.initial):
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

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> State:
        return State(self.t, self._p, self._dp, self._q, self._dq, self._side, self._y, self._v)

    @property
    def in_contact(self) -> bool:
        return self._side != FREE

    def deflection(self, side: int) -> float:
        """Tip deflection (m) of the barrier on ``side`` (+1 right, -1 left); 0 when not in contact."""
        if self._side != side:
            return 0.0
        return max(0.0, side * (self._q - self._p) - self.params.d / 2)

    def voltage(self, side: int) -> float:
        """Patch voltage (V) of the barrier on ``side`` (+1 right, -1 left).

        ``voltage_model = 0``: quasi-static, ``k_V`` times its deflection (0 when not in contact).
        1 and 2: the voltage across the load, exact; it can be negative (while the deflection
        falls) and decays through the load between contacts.
        """
        if not self._vm:
            return self.barrier.k_V * self.deflection(side)
        return self._circuit_now(side)[0]

    def power(self, side: int) -> float:
        """Instantaneous power (W) into the load of the barrier on ``side``, ``V^2 / R``.

        0 under ``voltage_model = 0``: the quasi-static voltage is an open-circuit voltage, no
        current flows and nothing is harvested (see ``Simulator.energy``).
        """
        if not self._vm:
            return 0.0
        v = self._circuit_now(side)[0]
        return v * v / self.params.R_load

    def _circuit_now(self, side: int) -> tuple[float, float]:
        """Voltage (V) of the barrier on ``side`` now, and its energy harvested so far (J)."""
        i = (side + 1) // 2
        br = self._bracket
        if self._piece is not None and side == self._side:
            # The barrier in contact, on the open bracket (booked at its start).
            return (self._piece.value(br.s, br.powers),
                    self._circuit_harvested[i] + self._piece.harvested(br.s, br.powers))
        v, harvested = decay(self._circuit_V[i], self.t - self._circuit_t[i], self._RC, self.barrier.C_p)
        return v, self._circuit_harvested[i] + harvested

    @property
    def base_force(self) -> float:
        """Force (N) the device exerts on its base through ``K`` and ``C``, positive along +x."""
        return self.params.K * (self._p - self._y) + self.params.C * (self._dp - self._v)

    @property
    def impacts(self) -> list[Impact]:
        """Logged contacts, oldest first, the one in progress (if any) last."""
        return list(self._impacts) + ([self._open] if self._open else [])

    @property
    def maxima(self) -> list[tuple[float, float]]:
        """Maxima ``(t, p)`` of the main-mass displacement (s, m), oldest first."""
        return list(self._maxima)

    @property
    def metrics(self) -> Metrics:
        # Metrics change only at events; a host reads them every step.
        if self._metrics is None:
            self._metrics = self._acc.metrics(self.params.R_load)
        return self._metrics

    @property
    def energy(self) -> EnergyLedger:
        p = self.params
        if self._side == FREE:
            kinetic = 0.5 * (p.M * self._dp**2 + p.m * self._dq**2)
            potential_Keq = 0.0
        else:
            kinetic = 0.5 * (self._M_contact * self._dp**2 + self._m_contact * self._dq**2)
            delta = self._side * (self._q - self._p) - p.d / 2
            potential_Keq = 0.5 * self.barrier.K_eq * delta**2
        a = self._accounts
        br = self._bracket
        open_C, open_Ceq, open_base = br.powers @ br.ledger if br else (0.0, 0.0, 0.0)
        if not self._vm:
            return EnergyLedger(kinetic=kinetic, potential_K=0.5 * p.K * (self._p - self._y) ** 2,
                                potential_Keq=potential_Keq, dissipated_C=a.dissipated_C + open_C,
                                dissipated_Ceq=a.dissipated_Ceq + open_Ceq, plastic=a.plastic,
                                work_base=a.work_base + open_base, initial=a.initial)
        v_left, harvested_left = self._circuit_now(LEFT)
        v_right, harvested_right = self._circuit_now(RIGHT)
        converted = self._circuit_converted
        if self._piece is not None:
            converted += self._piece.converted(br.s, br.powers)
        return EnergyLedger(kinetic=kinetic, potential_K=0.5 * p.K * (self._p - self._y) ** 2,
                            potential_Keq=potential_Keq, dissipated_C=a.dissipated_C + open_C,
                            dissipated_Ceq=a.dissipated_Ceq + open_Ceq, plastic=a.plastic,
                            work_base=a.work_base + open_base, initial=a.initial,
                            electrical=0.5 * self.barrier.C_p * (v_left * v_left + v_right * v_right),
                            harvested_left=harvested_left, harvested_right=harvested_right,
                            converted=converted, electrical_work=converted if self._vm == COUPLED else 0.0)

    @property
    def contact_frequency(self) -> float:
        """rad/s: undamped angular frequency ``sqrt(K_eq / mu)`` of the relative motion in contact
        (short-circuited patch), ``mu`` the reduced mass of ``M - M_eq`` and ``m + M_eq``."""
        mu = self._M_contact * self._m_contact / (self._M_contact + self._m_contact)
        return math.sqrt(self.barrier.K_eq / mu)

    @property
    def bracket_lengths(self) -> dict[str, float]:
        """Longest bracket (s) of each phase: ``THETA / rho(A)`` (see ``propagation.py``)."""
        return {"free": self._free.h, "contact": self._contact[RIGHT].h}

    @property
    def longest_bracket(self) -> float:
        """The longest bracket (s) of any phase."""
        return max(self._free.h, self._contact[RIGHT].h)

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
                self._accounts.work_base += jump
            self._y, self._v = float(y), float(v)
        instant_switches = 0
        while True:
            if self._bracket is None:
                self._bracket = self._open_bracket()
                self.brackets_opened += 1
            br = self._bracket
            s_stop = min(1.0, (t_end - br.t_start) / br.tau)
            s_to = min(s_stop, br.s_switch)
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

    def _move_to(self, br: "_Bracket", s: float, t: float) -> None:
        """Set the state to the bracket's trajectory at normalised time ``s`` (time ``t``)."""
        br.powers = powers(s)
        u, w, du, dw = (br.powers[:STATE_TERMS] @ br.c).tolist()[:4]
        base = br.base + br.v * s * br.tau
        self.t = t
        self._p, self._q = u + base, w + base
        self._dp, self._dq = du + br.v, dw + br.v
        self._y = base
        br.s = s

    def _open_bracket(self) -> "_Bracket":
        """A new bracket from the present state, with every event on it located."""
        side, y, v = self._side, self._y, self._v
        phase = self._free if side == FREE else self._contact[side]
        x = np.array([self._p - y, self._q - y, self._dp - v, self._dq - v, 1.0])
        if side != FREE and self._vm:
            if self._vm == COUPLED:
                x = np.append(x, self._circuit_V[(side + 1) // 2])
            c = phase.coefficients(x, phase.h)
            self._piece = self._contact_piece(c, phase.h, side)
        else:
            c = phase.coefficients(x, phase.h)
        # The largest size of each state column: the rounding level of the event functions below,
        # and (NaN and inf propagate through it) the test that the bracket is finite.
        column_size = np.abs(c).max(axis=0)
        if not np.isfinite(column_size).all():
            # Root isolation would halve NaN coefficients down to 2**-40: refuse instead.
            raise ValueError(f"y = {y!r} m, v = {v!r} m/s at t = {self.t!r} s: the state (p = {self._p!r} m, "
                             f"q = {self._q!r} m, p' = {self._dp!r} m/s, q' = {self._dq!r} m/s) overflows double "
                             "precision on the next bracket; allowed range: base and state well below 1e150")
        br = _Bracket(c=c, t_start=self.t, tau=phase.h, base=y, v=v, ledger=self._ledger_integrands(c, phase.h, side, v))
        # Event functions as linear maps of the state: columns of G, Bernstein rows of B, and
        # the rounding level of each (a few ulp of the state terms that make it up).
        functionals, magnitudes = self._event_maps(side, v)
        G = c @ functionals
        B = bernstein(G.T)
        noise = _NOISE_ULPS * EPS * (column_size @ magnitudes)
        n_terminal = 2 if side == FREE else 1
        direction = +1 if side == FREE else -1
        targets = (RIGHT, LEFT) if side == FREE else (FREE,)
        # Most event functions have no sign change on a bracket: one test of all of them first.
        may = may_cross(B)
        for j in range(n_terminal):
            g, b = G[:, j], B[j]
            if abs(g[0]) <= max(self._zero, noise[j]):
                # At a switch the function that fired is zero to rounding: its sign just after
                # the start is that of the relative velocity towards the barrier. When that is
                # zero to rounding too (a body coming to rest on a barrier), the relative
                # acceleration without the barrier's force decides. Both tests read the same
                # state the same way in either phase, so the phases cannot hand over to each
                # other forever at one instant.
                g = g.copy()
                g[0] = 0.0
                barrier = targets[j] if side == FREE else side
                rate = barrier * (x[DW] - x[DU])
                if abs(rate) > _NOISE_ULPS * EPS * (abs(x[DW]) + abs(x[DU])):
                    start = int(np.sign(rate))
                else:
                    start = self._approach_sign(x, barrier)
                if start == direction:
                    br.s_switch, br.switch_to = 0.0, targets[j]
                    return br
                b = bernstein(g)
            elif not may[j]:
                continue
            roots = crossings(g, direction, b, noise[j])
            if roots and roots[0] < br.s_switch:
                br.s_switch, br.switch_to = roots[0], targets[j]
        # Non-terminal events before the switch: maxima of p and, in contact, peaks of delta.
        events = [(s, _MAXIMUM) for s in crossings(G[:, 2], -1, B[2], noise[2]) if s <= br.s_switch] if may[2] else []
        if side != FREE:
            br.delta = G[:, 0]
            if may[1]:
                events += [(s, _PEAK) for s in crossings(G[:, 1], -1, B[1], noise[1]) if s <= br.s_switch]
            if self._piece is not None:
                events += [(s, _VOLTAGE_PEAK) for s in self._piece.peaks(min(br.s_switch, 1.0))]
            events.sort()
        br.events = events
        return br

    def _event_maps(self, side: int, v: float) -> tuple[np.ndarray, np.ndarray]:
        """The event functionals of ``side`` for base velocity ``v``, and their absolute values."""
        functionals = self._functionals[side]
        if functionals[ONE, 2] != v or side not in self._magnitudes:
            functionals[ONE, 2] = v  # p' = u' + v
            self._magnitudes[side] = np.abs(functionals)
        return functionals, self._magnitudes[side]

    def _ledger_integrands(self, c: np.ndarray, tau: float, side: int, v: float) -> np.ndarray:
        """Primitives, in normalised time, of the ledger's rates on a bracket (J).

        Columns: dissipation in ``C`` (``C u'^2``), in ``C_eq`` (``C_eq delta'^2``), and the work
        of the base (``-v (K u + C u')``: minus the force the device exerts on it, times ``v``).
        """
        p = self.params
        P = np.zeros((PRIMITIVE_TERMS, 3))
        primitive_of_square(c[:, DU], p.C * tau, out=P[:, 0])
        if side != FREE:
            primitive_of_square(c[:, DW] - c[:, DU], p.C_eq * tau, out=P[:, 1])
        if v != 0.0:
            primitive(p.K * c[:, U] + p.C * c[:, DU], -v * tau, out=P[:, 2])
        return P

    def _contact_piece(self, c: np.ndarray, tau: float, side: int) -> Piece:
        """The voltage of the barrier on ``side`` over a contact bracket (``circuit.py``)."""
        chi, R = self.barrier.chi, self.params.R_load
        D = side * (c[:, DW] - c[:, DU])  # delta' (m/s)
        if self._vm == COUPLED:
            return Piece(c[:, VOLT].copy(), 0.0, tau / self._RC, D, tau, R, chi)
        return driven(self._circuit_V[(side + 1) // 2], D, tau / self._RC, tau * chi / self.barrier.C_p, tau, R, chi)

    def _approach_sign(self, x: np.ndarray, side: int) -> int:
        """Sign of the relative acceleration of the impact mass towards the barrier on ``side``
        from the main spring and damper alone (the barrier's force left out), at state ``x``."""
        main_acceleration = -(self.params.K * x[U] + self.params.C * x[DU])
        return int(np.sign(-side * main_acceleration))

    def _non_terminal_event(self, br: "_Bracket", s: float, kind: int) -> None:
        if kind == _MAXIMUM:
            p = float(evaluate(br.c[:, U], s)) + br.base + br.v * s * br.tau
            self._record_maximum(br.t_start + s * br.tau, p)
        elif kind == _PEAK:
            self._open.max_deflection = max(self._open.max_deflection, float(evaluate(br.delta, s)))
        else:
            self._circuit_peak = max(self._circuit_peak, abs(self._piece.value(s, powers(s))))

    def _close_bracket(self) -> None:
        """Book the ledger of the present bracket up to where the state stands, and drop it.

        The ledger of an open bracket is read from its primitives at the present position, and
        booked only when the bracket closes; so the ledger, like the state, does not depend on
        how the calls chopped the bracket.
        """
        br = self._bracket
        if br is None:
            return
        dissipated_C, dissipated_Ceq, work_base = br.powers @ br.ledger
        a = self._accounts
        a.dissipated_C += dissipated_C
        a.dissipated_Ceq += dissipated_Ceq
        a.work_base += work_base
        self._bracket = None
        if self._vm and self._piece is not None:
            # Book the voltage of the barrier in contact where the state stands.
            piece, i = self._piece, (self._side + 1) // 2
            v = piece.value(br.s, br.powers)
            self._circuit_V[i], self._circuit_t[i] = v, self.t
            self._circuit_harvested[i] += piece.harvested(br.s, br.powers)
            self._circuit_converted += piece.converted(br.s, br.powers)
            self._circuit_peak = max(self._circuit_peak, abs(v))
            self._piece = None

    def _record_maximum(self, t: float, p: float) -> None:
        self._metrics = None
        self._maxima.append((t, p))
        self._acc.maximum(t, p)

    def _switch(self, to: int) -> None:
        """Apply the momentum-exact switch rules of MODEL.md section 3 at the present time."""
        self._metrics = None
        M_eq = self.barrier.M_eq
        dp, dq = self._dp, self._dq
        if to != FREE:
            m = self.params.m
            dq_after = (m * dq + M_eq * dp) / (m + M_eq)
            loss = 0.5 * m * M_eq / (m + M_eq) * (dq - dp) ** 2
            self._open = Impact(time=self.t, side=to, rel_velocity=dq - dp, dp_before=dp, dq_before=dq,
                                dp_after=dp, dq_after=dq_after, capture_loss=loss)
            self._acc.impact_started()
            self._dq = dq_after
            if self._vm:
                # The barrier's voltage decayed since it was booked; the contact starts from it.
                i = (to + 1) // 2
                v, harvested = decay(self._circuit_V[i], self.t - self._circuit_t[i], self._RC, self.barrier.C_p)
                self._circuit_V[i], self._circuit_t[i] = v, self.t
                self._circuit_harvested[i] += harvested
                self._circuit_peak = abs(v)
        else:
            M = self.params.M
            dp_after = (self._M_contact * dp + M_eq * dq) / M
            loss = 0.5 * self._M_contact * M_eq / M * (dp - dq) ** 2
            impact = self._open
            impact.duration = self.t - impact.time
            if self._vm:
                impact.voltage = self._circuit_peak  # peak |V| over the contact, ends included
            else:
                impact.voltage = self.barrier.k_V * impact.max_deflection
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
        self._accounts.plastic += loss
        self._side = to

    # ------------------------------------------------------------------ saving state
    def snapshot(self) -> dict:
        """The full internal state as a JSON-safe dict (floats, ints, lists)."""
        data = {
            "t": self.t, "p": self._p, "dp": self._dp, "q": self._q, "dq": self._dq,
            "side": self._side, "y": self._y, "v": self._v,
            "accounts": asdict(self._accounts), "metrics": self._acc.to_dict(),
            "open": asdict(self._open) if self._open else None,
            "impacts": [asdict(i) for i in self._impacts],
            "maxima": [list(m) for m in self._maxima],
            "bracket": self._bracket.to_dict() if self._bracket else None,
        }
        if self._vm:
            # The voltage on an open contact bracket is rebuilt from the bracket and the booked V.
            data["circuit"] = {"V": list(self._circuit_V), "t": list(self._circuit_t),
                               "harvested": list(self._circuit_harvested),
                               "converted": self._circuit_converted, "peak": self._circuit_peak}
        return data

    @classmethod
    def restore(cls, params: Parameters, snapshot: dict, log_limit: int | None = None) -> "Simulator":
        """A simulator of ``params`` in the state saved by :meth:`snapshot`."""
        sim = cls(params, log_limit=log_limit)
        sim.t = float(snapshot["t"])
        sim._p, sim._dp, sim._q, sim._dq = (float(snapshot[k]) for k in ("p", "dp", "q", "dq"))
        sim._side = int(snapshot["side"])
        sim._y, sim._v = float(snapshot["y"]), float(snapshot["v"])
        sim._accounts = _Accounts(**snapshot["accounts"])
        sim._acc = MetricAccumulators.from_dict(snapshot["metrics"])
        sim._open = Impact(**snapshot["open"]) if snapshot["open"] else None
        sim._impacts.extend(Impact(**i) for i in snapshot["impacts"])
        sim._maxima.extend(tuple(m) for m in snapshot["maxima"])
        sim._bracket = _Bracket.from_dict(snapshot["bracket"]) if snapshot["bracket"] else None
        if sim._vm:
            if "circuit" not in snapshot:
                raise ValueError(f"the snapshot has no circuit state: it was saved under voltage_model = 0, "
                                 f"not {params.voltage_model}")
            circuit = snapshot["circuit"]
            sim._circuit_V = [float(v) for v in circuit["V"]]
            sim._circuit_t = [float(t) for t in circuit["t"]]
            sim._circuit_harvested = [float(h) for h in circuit["harvested"]]
            sim._circuit_converted = float(circuit["converted"])
            sim._circuit_peak = float(circuit["peak"])
            if sim._bracket is not None and sim._side != FREE:
                sim._piece = sim._contact_piece(sim._bracket.c, sim._bracket.tau, sim._side)
        return sim


def _event_functionals(side: int, d: float, n: int = 5) -> np.ndarray:
    """Event functions of a phase as columns acting on x = (u, w, u', w', 1) (and V, n = 6).

    Free flight: ``r - d/2``, ``-r - d/2`` (onsets, right and left) and ``p'``; contact on
    ``side``: ``delta`` (separation), ``delta'`` (its peak) and ``p'``. The base velocity in
    ``p' = u' + v`` is filled in per bracket.
    """
    L = np.zeros((n, 3))
    if side == FREE:
        L[[U, W], 0] = [-1.0, 1.0]
        L[[U, W], 1] = [1.0, -1.0]
        L[ONE, :2] = -d / 2
    else:
        L[[U, W], 0] = [-side, side]
        L[ONE, 0] = -d / 2
        L[[DU, DW], 1] = [-side, side]
    L[DU, 2] = 1.0
    return L


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



def _free_matrix(M: float, K: float, C: float) -> np.ndarray:
    """Free flight on x = (u, w, u', w', 1): M u'' + C u' + K u = 0, w'' = 0."""
    A = np.zeros((5, 5))
    A[U, DU] = A[W, DW] = 1.0
    A[DU, U] = -K / M
    A[DU, DU] = -C / M
    return A


def _contact_matrix(M1: float, m1: float, K: float, C: float, K_eq: float, C_eq: float, d: float, side: int,
                    coupling: tuple[float, float, float] | None = None) -> np.ndarray:
    """Contact with the barrier on ``side`` (MODEL.md section 3) on x = (u, w, u', w', 1).

    ``s F = K_eq (w - u) + C_eq (w' - u') - s K_eq d/2`` acts on the main body (mass ``M1``)
    and its opposite on the impact body (mass ``m1``). With ``coupling = (chi, C_p, R)``
    (``voltage_model = 2``) the state is x = (u, w, u', w', 1, V): the patch voltage adds
    ``chi V`` to the contact force ``F`` and obeys ``C_p V' + V / R = chi delta'``.
    """
    n = 5 if coupling is None else 6
    force = np.zeros(n)
    force[[U, W, DU, DW]] = [-K_eq, K_eq, -C_eq, C_eq]
    force[ONE] = -side * K_eq * d / 2
    A = np.zeros((n, n))
    if coupling is not None:
        chi, C_p, R = coupling
        force[VOLT] = side * chi
        A[VOLT, [DU, DW]] = [-side * chi / C_p, side * chi / C_p]
        A[VOLT, VOLT] = -1.0 / (R * C_p)
    A[U, DU] = A[W, DW] = 1.0
    A[DU] = force / M1
    A[DU, U] -= K / M1
    A[DU, DU] -= C / M1
    A[DW] = -force / m1
    return A
