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
import operator
from collections import deque
from functools import lru_cache
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import numpy as np

from .barrier import derive_barrier
from .circuit import Piece, decay, driven
from .metrics import MetricAccumulators, Metrics
from .parameters import COUPLED, Parameters
from .propagation import (MIN_BRACKET, POWERS_AT_END, POWERS_AT_START, PRIMITIVE_TERMS, STATE_TERMS, LinearPhase, powers,
                          primitive, primitive_of_square)
from .roots import _TO_BERNSTEIN, crossings, horner

FREE = 0
RIGHT = +1
LEFT = -1
#: Switches allowed at one instant before the run is declared degenerate.
MAX_SWITCHES_AT_ONE_INSTANT = 8
#: Relative size, against the gap, under which an event function at a bracket start is zero.
_ZERO = 1e-13
#: Rounding level of an event function, in ulp of the largest state term it is made of.
_NOISE_ULPS = 64
#: Largest size of the terms of a bracket (state, event functions, the ledger's rates): their
#: squares, in the ledger, stay inside double range.
_STATE_LIMIT = 1e150
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
#: ``1 / (j + k + 1)``: the integrals over [0, 1] of products of powers (``_ledger_integrals``).
_HILBERT = 1.0 / (np.arange(STATE_TERMS)[:, None] + np.arange(STATE_TERMS)[None, :] + 1.0)


@dataclass(slots=True)
class _Bracket:
    """One bracket of the present phase: its exact trajectory and its located events.

    ``c`` holds the Taylor coefficients of the deviation state over ``[t_start, t_start + tau]``
    (normalised time ``s`` in [0, 1]); ``base`` (m) and ``v`` (m/s) are the base there. The
    phase switches at ``s_switch`` (inf: not in this bracket) to side ``switch_to``; ``events``
    are the non-terminal events ``(s, kind)`` still ahead; ``s`` is where the state stands.
    ``rates`` holds the ledger's rates over the bracket (``_ledger_rates``), and ``ledger``
    their primitives once the ledger of the open bracket has been read.
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
    rates: np.ndarray | None = None
    ledger: np.ndarray | None = None
    #: ``s**k`` at the present position, k < PRIMITIVE_TERMS: serves the state and the ledger.
    powers: np.ndarray = field(default_factory=lambda: POWERS_AT_START)

    def to_dict(self) -> dict:
        data = asdict(self)
        for name in ("c", "delta", "rates", "ledger", "powers"):
            value = getattr(self, name)
            data[name] = None if value is None else value.tolist()
        data["events"] = [list(e) for e in self.events]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "_Bracket":
        data = dict(data)
        for name in ("c", "delta", "rates", "ledger", "powers"):
            if data[name] is not None:
                data[name] = np.array(data[name], dtype=float)
        data["events"] = [(float(s), int(k)) for s, k in data["events"]]
        return cls(**data)


#: Closed brackets whose ledger is booked in one set of products (``Simulator._book_pending``).
_LEDGER_BATCH = 64


class _PendingLedger:
    """The rates and positions of closed brackets not booked yet (at most ``_LEDGER_BATCH``), in
    arrays made once: the memory of a run does not grow with it."""

    def __init__(self):
        self.rates = np.empty((_LEDGER_BATCH, 3, STATE_TERMS))
        self.powers = np.empty((_LEDGER_BATCH, STATE_TERMS))
        self.span = np.empty(_LEDGER_BATCH)
        self.v = np.empty(_LEDGER_BATCH)
        self.count = 0


def _ledger_integrals(rates: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """For brackets stopped at ``s`` (``powers`` = ``s^k``), shape (brackets, 3): the integrals
    over ``[0, s]`` of the squares of the first two rates and of the third, divided by ``s``.

    ``int_0^s a(r)^2 dr = s (a p)^T H (a p)`` with ``p_k = s^k`` and the Hilbert matrix
    ``H_jk = 1 / (j + k + 1)``, whose first row also gives ``int_0^s a(r) dr = s H[0] (a p)``:
    the same integrals as the primitives of ``Simulator._open_ledger``, to rounding."""
    scaled = rates * powers[:, None, :]
    weighted = scaled @ _HILBERT
    integrals = np.add.reduce(scaled * weighted, axis=2)
    integrals[:, 2] = weighted[:, 2, 0]
    return integrals


class _BracketMaps:
    """The linear maps a bracket of one phase needs from its start state ``x``, stacked as
    columns so that one product ``x @ stacked`` gives them all:

    - the Taylor coefficients of the state (ORDER+1 rows of n);
    - the power and the Bernstein coefficients of the three event functions (``functionals``,
      with the base velocity left out of ``p'``), ORDER+1 each;
    - the power coefficients of the ledger's rates (``Simulator._ledger_rates``): ``u'``,
      ``delta'`` (zero in free flight) and ``K u + C u'``.
    """

    def __init__(self, phase: LinearPhase, functionals: np.ndarray, rates: np.ndarray):
        self.phase = phase
        terms = phase.bracket_terms  # (k, i, j)
        n = terms.shape[1]
        power = (np.concatenate([functionals, rates], axis=1).T @ terms).transpose(1, 0, 2)  # (row, k, j)
        bernstein_rows = _TO_BERNSTEIN.T @ power[:3]
        self.stacked = np.ascontiguousarray(
            np.concatenate([terms.reshape(-1, n), power.reshape(-1, n), bernstein_rows.reshape(-1, n)]).T)
        #: Where the state's coefficients end and the rows of the functions begin.
        self.split = STATE_TERMS * n
        #: Rows (one per event function) of ``sum_i |functional_i| max_k |terms_k[i, j]|``: with the
        #: sizes ``|x_j|`` of the start state, a bound on the state terms an event function is made of.
        self.noise_rows = (np.abs(functionals).T @ np.abs(terms).max(axis=0)).tolist()
        #: Sums of those rows: times the sum of the ``|x_j|``, a bound on the rounding level.
        self.noise_bounds = [sum(row) for row in self.noise_rows]
        #: The largest column sum of ``|stacked|``: times the sum of the ``|x_j|``, a bound on the
        #: size of everything a bracket is made of.
        self.size_bound = float(np.abs(self.stacked).sum(axis=0).max())

    def mirrored(self, phase: LinearPhase, signs: np.ndarray) -> "_BracketMaps":
        """The maps of the other barrier: its phase is this one's mirrored by ``signs``
        (``LinearPhase.mirrored``), and its event functions ``delta`` and ``delta'`` are this one's
        in the mirrored state, negated (``_event_functionals``); the rates are the same."""
        mirror = object.__new__(_BracketMaps)
        mirror.phase, mirror.split, mirror.noise_rows, mirror.noise_bounds = phase, self.split, self.noise_rows, self.noise_bounds
        mirror.size_bound = self.size_bound
        mirror.stacked = self.stacked * signs[:, None] * _mirror_rows(len(signs))
        return mirror


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
        self._free = LinearPhase(_free_matrix(M, K, C), _free_spectral_radius(M, K, C))
        #: The voltage model: 0 quasi-static (no circuit state), 1 circuit one-way, 2 coupled.
        self._vm = params.voltage_model
        #: The voltage of the barrier in contact on the open bracket (voltage_model 1 and 2).
        self._piece: Piece | None = None
        coupling = None
        if self._vm == COUPLED:
            coupling = (self.barrier.chi, self.barrier.C_p, params.R_load)
        right = LinearPhase(_contact_matrix(self._M_contact, self._m_contact, K, C, K_eq, C_eq, params.d, RIGHT, coupling))
        # The left barrier is the right one seen with the signs of the constant (and the voltage)
        # turned over: exact sign changes, not a second series.
        self._contact = {RIGHT: right, LEFT: right.mirrored(_mirror_signs(right.A.shape[0]))}
        _check_time_scales(params, self._free, self._contact[RIGHT])
        self._zero = _ZERO * params.d
        n = right.A.shape[0]
        self._maps = {side: _BracketMaps(self._free if side == FREE else right, _event_functionals(side, params.d, 5 if side == FREE else n),
                                         _ledger_rates(side, K, C, 5 if side == FREE else n))
                      for side in (FREE, RIGHT)}
        self._maps[LEFT] = self._maps[RIGHT].mirrored(self._contact[LEFT], _mirror_signs(n))
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
        self._pending = _PendingLedger()
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
        self._book_pending()
        a = self._accounts
        br = self._bracket
        open_C, open_Ceq, open_base = self._open_ledger(br) if br else (0.0, 0.0, 0.0)
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
        br.powers = POWERS_AT_END if s == 1.0 else powers(s)
        u, w, du, dw = np.dot(br.powers[:STATE_TERMS], br.c).tolist()[:4]
        base = br.base + br.v * s * br.tau
        self.t = t
        self._p, self._q = u + base, w + base
        self._dp, self._dq = du + br.v, dw + br.v
        self._y = base
        br.s = s

    def _open_bracket(self) -> "_Bracket":
        """A new bracket from the present state, with every event on it located."""
        side, y, v = self._side, self._y, self._v
        maps = self._maps[side]
        phase = maps.phase
        xs = [self._p - y, self._q - y, self._dp - v, self._dq - v, 1.0]
        if side != FREE and self._vm == COUPLED:
            xs.append(self._circuit_V[(side + 1) // 2])
        sizes = list(map(abs, xs))
        total = sum(sizes)  # NaN and inf propagate through it
        if not total * maps.size_bound < _STATE_LIMIT:
            # Root isolation would halve NaN coefficients down to 2**-40: refuse instead.
            raise ValueError(f"y = {y!r} m, v = {v!r} m/s at t = {self.t!r} s: the state (p = {self._p!r} m, "
                             f"q = {self._q!r} m, p' = {self._dp!r} m/s, q' = {self._dq!r} m/s) overflows double "
                             "precision on the next bracket; allowed range: base and state well below 1e150")
        # One product gives the Taylor coefficients of the state, and the power and Bernstein
        # coefficients of the event functions (rows; the base velocity enters p' = u' + v below).
        z = np.array(xs) @ maps.stacked
        functions = z[maps.split:].reshape(9, STATE_TERMS)  # event functions, rates, Bernstein rows
        c, G, rates, B = z[:maps.split].reshape(STATE_TERMS, -1), functions[:3], functions[3:6], functions[6:]
        if v != 0.0:
            G[2, 0] += v
            B[2] += v
        if side != FREE and self._vm:
            self._piece = self._contact_piece(c, phase.h, side)
        br = _Bracket(c=c, t_start=self.t, tau=phase.h, base=y, v=v, rates=rates)
        # The rounding level of each event function: a few ulp of the largest state terms that
        # make it up, bounded from the start state (made only for the functions that need it).
        noise_rows = maps.noise_rows
        n_terminal = 2 if side == FREE else 1
        direction = +1 if side == FREE else -1
        targets = (RIGHT, LEFT) if side == FREE else (FREE,)
        values = B.tolist()
        for j in range(n_terminal):
            g, b, row = G[j], B[j], values[j]
            start_value = row[0]  # the first Bernstein coefficient is the value at the start
            near_zero = abs(start_value) <= max(self._zero, _NOISE_ULPS * EPS * maps.noise_bounds[j] * total)
            if not near_zero and (min(row) > 0.0 or max(row) < 0.0):
                continue  # one strict sign, away from zero at the start: no root
            noise = _rounding(noise_rows[j], sizes)
            if near_zero and abs(start_value) <= max(self._zero, noise):
                # At a switch the function that fired is zero to rounding: its sign just after
                # the start is that of the relative velocity towards the barrier. When that is
                # zero to rounding too (a body coming to rest on a barrier), the relative
                # acceleration without the barrier's force decides. Both tests read the same
                # state the same way in either phase, so the phases cannot hand over to each
                # other forever at one instant.
                barrier = targets[j] if side == FREE else side
                rate = barrier * (xs[DW] - xs[DU])
                if abs(rate) > _NOISE_ULPS * EPS * (sizes[DW] + sizes[DU]):
                    start = 1 if rate > 0.0 else -1
                else:
                    start = self._approach_sign(xs, barrier)
                if start == direction:
                    br.s_switch, br.switch_to = 0.0, targets[j]
                    return br
                # The start value set to zero: every Bernstein coefficient holds it with weight 1.
                # Most often the rest then has one strict sign (rounding is monotonic, so the
                # extremes of the shifted coefficients are the shifted extremes): no root.
                rest = row[1:]
                if min(rest) - start_value > 0.0 or max(rest) - start_value < 0.0:
                    continue
                g = g.copy()
                g[0] = 0.0
                b = b - start_value
                row = [value - start_value for value in row]
            roots = crossings(g, direction, b, noise, row)
            if roots and roots[0] < br.s_switch:
                br.s_switch, br.switch_to = roots[0], targets[j]
        # Non-terminal events before the switch: maxima of p and, in contact, peaks of delta.
        events = [(s, _MAXIMUM) for s in self._falls(G, B, values, 2, sizes, noise_rows, v) if s <= br.s_switch]
        if side != FREE:
            br.delta = G[0]
            events += [(s, _PEAK) for s in self._falls(G, B, values, 1, sizes, noise_rows, v) if s <= br.s_switch]
            if self._piece is not None:
                events += [(s, _VOLTAGE_PEAK) for s in self._piece.peaks(min(br.s_switch, 1.0))]
            events.sort()
        br.events = events
        return br

    @staticmethod
    def _falls(G: np.ndarray, B: np.ndarray, values: list, j: int, sizes: list[float], noise_rows: list,
               v: float) -> list[float]:
        """Where event function ``j`` falls through zero: maxima of ``p`` (j = 2, where the base
        velocity adds to the rounding level) and peaks of ``delta`` (j = 1, in contact)."""
        row = values[j]
        if min(row) > 0.0 or max(row) < 0.0:
            return []
        noise = _rounding(noise_rows[j], sizes) + (_NOISE_ULPS * EPS * abs(v) if j == 2 else 0.0)
        return crossings(G[j], -1, B[j], noise, row)

    def _contact_piece(self, c: np.ndarray, tau: float, side: int) -> Piece:
        """The voltage of the barrier on ``side`` over a contact bracket (``circuit.py``)."""
        chi, R = self.barrier.chi, self.params.R_load
        D = side * (c[:, DW] - c[:, DU])  # delta' (m/s)
        if self._vm == COUPLED:
            return Piece(c[:, VOLT].copy(), 0.0, tau / self._RC, D, tau, R, chi)
        return driven(self._circuit_V[(side + 1) // 2], D, tau / self._RC, tau * chi / self.barrier.C_p, tau, R, chi)

    def _approach_sign(self, x: list[float], side: int) -> int:
        """Sign of the relative acceleration of the impact mass towards the barrier on ``side``
        from the main spring and damper alone (the barrier's force left out), at state ``x``."""
        towards = side * (self.params.K * x[U] + self.params.C * x[DU])  # -side * main acceleration
        return (towards > 0.0) - (towards < 0.0)

    def _non_terminal_event(self, br: "_Bracket", s: float, kind: int) -> None:
        if kind == _MAXIMUM:
            p = horner(br.c[:, U].tolist(), s) + br.base + br.v * s * br.tau
            self._record_maximum(br.t_start + s * br.tau, p)
        elif kind == _PEAK:
            self._open.max_deflection = max(self._open.max_deflection, horner(br.delta.tolist(), s))
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
        pending = self._pending
        i = pending.count
        pending.rates[i] = br.rates
        pending.powers[i] = br.powers[:STATE_TERMS]
        pending.span[i] = br.tau * br.s  # s, normalised, times the bracket's length
        pending.v[i] = br.v
        pending.count = i + 1
        if i + 1 == _LEDGER_BATCH:
            self._book_pending()
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

    def _open_ledger(self, br: "_Bracket") -> tuple[float, float, float]:
        """Dissipation in ``C`` and ``C_eq`` and work of the base (J) on the bracket so far, read
        from the primitives of the rates (made on the first reading of the bracket: a host that
        reads the ledger every step pays one product per reading)."""
        if br.ledger is None:
            u_rate, delta_rate, force = br.rates
            weights = self._ledger_factors(br.tau, br.v)
            br.ledger = np.zeros((3, PRIMITIVE_TERMS))
            primitive_of_square(u_rate, weights[0], out=br.ledger[0])
            primitive_of_square(delta_rate, weights[1], out=br.ledger[1])
            primitive(force, weights[2], out=br.ledger[2])
        return tuple((br.ledger @ br.powers).tolist())

    def _booked_ledger(self, br: "_Bracket") -> tuple[float, float, float]:
        """What closing the bracket now would book (``_book_pending``)."""
        squares = _ledger_integrals(br.rates[None], br.powers[None, :STATE_TERMS])[0].tolist()
        weights = self._ledger_factors(br.tau * br.s, br.v)
        return weights[0] * squares[0], weights[1] * squares[1], weights[2] * squares[2]

    def _book_pending(self) -> None:
        """Book the ledger of the closed brackets not booked yet, in one set of products: the
        same whether a host read the ledger in between or not, to rounding."""
        pending = self._pending
        n = pending.count
        if not n:
            return
        integrals = _ledger_integrals(pending.rates[:n], pending.powers[:n])
        factors = self._ledger_factors(pending.span[:n], pending.v[:n])
        booked = [(integrals[:, k] * factors[k]).tolist() for k in range(3)]
        a = self._accounts
        a.dissipated_C += math.fsum(booked[0])
        a.dissipated_Ceq += math.fsum(booked[1])
        a.work_base += math.fsum(booked[2])
        pending.count = 0

    def _ledger_factors(self, span, v):
        """Factors of the ledger's rates: ``C``, ``C_eq`` and ``-v``, times ``span``, the time the
        bracket has run (the rates are polynomials in normalised time; ``_ledger_integrals``).
        Floats for one bracket, arrays for a batch."""
        return self.params.C * span, self.params.C_eq * span, -v * span

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
        self._book_pending()
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
    ``p' = u' + v`` is added per bracket (``_open_bracket``).
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


@lru_cache(maxsize=None)
def _mirror_rows(n: int) -> np.ndarray:
    """The column signs of ``_BracketMaps.stacked`` between the barriers, for states of size ``n``:
    the state's terms like the state, ``delta`` and ``delta'`` negated, ``p'`` and the rates kept."""
    events = np.repeat([-1.0, -1.0, 1.0], STATE_TERMS)
    rows = np.concatenate([np.tile(_mirror_signs(n), STATE_TERMS), events, np.ones(3 * STATE_TERMS), events])
    rows.flags.writeable = False
    return rows


def _mirror_signs(n: int) -> np.ndarray:
    """``S`` with ``A_left = S A_right S`` (``_contact_matrix``): the constant (and the voltage)
    change sign, the displacements and velocities do not."""
    signs = np.ones(n)
    signs[ONE:] = -1.0
    return signs


def _rounding(row: list[float], sizes: list[float]) -> float:
    """The rounding level of an event function: ``_NOISE_ULPS`` ulp of the bound on its terms
    made from one row of ``_BracketMaps.noise_rows`` and the sizes of the start state."""
    return _NOISE_ULPS * EPS * sum(map(operator.mul, row, sizes))


def _ledger_rates(side: int, K: float, C: float, n: int = 5) -> np.ndarray:
    """The ledger's rates as columns acting on the state: ``u'``, ``delta'`` (squared, so its sign
    does not matter; zero in free flight) and ``K u + C u'`` (minus the force on the base)."""
    R = np.zeros((n, 3))
    R[DU, 0] = 1.0
    if side != FREE:
        R[[DU, DW], 1] = [-1.0, 1.0]
    R[[U, DU], 2] = [K, C]
    return R


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


def _free_spectral_radius(M: float, K: float, C: float) -> float:
    """1/s: the largest ``|lambda|`` of ``M lambda^2 + C lambda + K = 0`` (the other eigenvalues
    of free flight are zero): ``sqrt(K / M)`` when underdamped, the faster decay rate otherwise."""
    a, b = C / (2.0 * M), K / M
    if a * a <= b:
        return math.sqrt(b)
    return a + math.sqrt(a * a - b)


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
