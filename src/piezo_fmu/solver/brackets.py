"""One bracket of a phase: its exact trajectory and every event on it.

A bracket is a stretch of at most ``h`` seconds of one phase (``propagation.py``), on which the
deviation state is a polynomial in the normalised time ``s in [0, 1]``. Opening a bracket
computes, in one matrix product from its start state, the Taylor coefficients of the state, the
power and Bernstein coefficients of the phase's event functions
(:func:`piezo_fmu.model.dynamics.event_functionals`) and the rates of the energy ledger
(:func:`piezo_fmu.model.energy.energy_rates`); then it locates the phase switch (the first
terminal event) and the non-terminal events before it (``roots.py``). In free flight those
searches are put off until a move may reach a root (:class:`Searches`), with the same results.
"""

from __future__ import annotations

import math
import operator
from dataclasses import asdict, dataclass, field
from functools import lru_cache

import numpy as np

from ..model.dynamics import DU, DW, FREE, LEFT, RIGHT, approach_sign, mirror_signs
from ..model.rounding import EPS, NOISE_ULPS
from .propagation import POWERS_AT_START, STATE_TERMS, LinearPhase
from .roots import _TO_BERNSTEIN, NEWTON_LAST, crossings

#: Non-terminal events: a maximum of ``p``, a peak of ``delta``, a peak of the circuit's ``|V|``.
MAXIMUM, PEAK, VOLTAGE_PEAK = 0, 1, 2
#: Largest size of the terms of a bracket (state, event functions, the ledger's rates): their
#: squares, in the ledger, stay inside double range.
STATE_LIMIT = 1e150
#: Put off the root searches of free flight until a move may reach a root (:class:`Searches`);
#: False locates every root when the bracket opens (the same roots: the tests compare both).
DEFER = True
#: How far (normalised time) beyond a move's end a put-off search is shown to have no root before
#: the move goes on without it: more than any last Newton step of the refinement (``NEWTON_LAST``).
DEFER_MARGIN = 2.0**-20
#: A function taken as zero at a phase start has left rounding once it passes this many times its
#: rounding level (:meth:`Searches.run`); below, it drifts or grazes by rounding.
EMERGE = 16.0
assert DEFER_MARGIN > NEWTON_LAST


@dataclass(slots=True)
class Bracket:
    """One bracket of the present phase: its exact trajectory and its located events.

    ``c`` holds the Taylor coefficients of the deviation state over ``[t_start, t_start + tau]``
    (normalised time ``s`` in [0, 1]); ``base`` (m) and ``v`` (m/s) are the base there. The
    phase switches at ``s_switch`` (inf: not in this bracket) to side ``switch_to``; ``events``
    are the non-terminal events ``(s, kind)`` still ahead; ``s`` is where the state stands.
    ``rates`` holds the ledger's rates over the bracket (``energy_rates``), and ``ledger``
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
    #: The root searches put off (free flight, :class:`Searches`); None once they have run: then
    #: ``s_switch``, ``switch_to`` and ``events`` are final.
    deferred: "Searches | None" = None

    def located_to(self, s: float) -> None:
        """Make ``s_switch``, ``switch_to`` and the events up to ``s`` those of the searches run
        when the bracket opened: run the put-off searches unless none has a root up to ``s``
        (called while ``deferred`` is set and ``s`` beyond what it has shown clear)."""
        if not self.deferred.clear_until(s):
            self.deferred.run(self)

    def to_dict(self) -> dict:
        if self.deferred is not None:
            self.deferred.run(self)  # a snapshot holds the bracket as it was always held
        data = asdict(self)
        del data["deferred"]
        for name in ("c", "delta", "rates", "ledger", "powers"):
            value = getattr(self, name)
            data[name] = None if value is None else value.tolist()
        data["events"] = [list(e) for e in self.events]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "Bracket":
        data = dict(data)
        for name in ("c", "delta", "rates", "ledger", "powers"):
            if data[name] is not None:
                data[name] = np.array(data[name], dtype=float)
        data["events"] = [(float(s), int(k)) for s, k in data["events"]]
        return cls(**data)


class Searches:
    """The root searches of one bracket (``roots.crossings``): its switch, then the maxima of ``p``
    and, in contact, the peaks of ``delta`` before it. The opener runs them at once in contact;
    in free flight it puts them off until a move may reach one of their roots.

    A free-flight bracket is ``THETA`` radians of the motion long, often many communication steps;
    when the base moves, each step opens a new bracket and uses only its start. Its searches (the
    contact onsets, the maxima of ``p``) are therefore run only when a move may reach a root: the
    integrator asks :meth:`clear_until` before each move, and a search that cannot have a root up to
    the move's end is skipped. When one may, all of them run (:meth:`run`) exactly as they would
    have when the bracket opened: the same functions, the same numbers, so the same roots, switch
    and events, to the bit.

    **Why a skipped search has no root there.** Let ``a`` be the polynomial a search refines (power
    coefficients), ``A = sum |a_k|``. On ``[0, s]`` it keeps the sign of ``a_0``, by at least
    ``|a_0| - sum_{k>=1} |a_k| s^k``. When that exceeds ``1e-6 A + 8 noise`` for ``s``
    :data:`DEFER_MARGIN` beyond the move's end, no root the search can report lies in the move:

    - the search (``roots.crossings``) refines a root only on an interval whose first Bernstein
      coefficient has the sign before the crossing and whose last has the sign after it, and it
      reports the end of an interval only where the last coefficient is zero within ``noise``.
      The end coefficients are the values at the ends, to the rounding of the coefficients and of
      their halving (below ``1e-12 A`` and a few ``noise``): on ``[0, s]`` they have the sign of
      ``a_0``, never zero;
    - so where ``a_0`` has the sign after the crossing, no interval that starts in ``[0, s]`` is
      refined, and none that ends there is reported;
    - where it has the sign before, none that ends in ``[0, s]`` is refined or reported, and one
      that ends beyond is refined from the left: every point the refinement tries in ``[0, s]``
      reads that sign (Horner's rounding is below ``1e-14 A``), and it stops only at a point that
      reads zero, or where its bracket of signs has closed on a point that read the other sign,
      or within ``NEWTON_LAST`` of a point where the value is at most ``NEWTON_LAST`` times the
      slope (``<= ORDER A``). Such a point lies beyond ``s``, so the root it gives lies beyond
      the move's end: :data:`DEFER_MARGIN` exceeds both ``NEWTON_LAST`` and a closed bracket's
      width.
    """

    __slots__ = ("contact", "terminal", "emerging", "maxima", "peaks", "clear", "fail", "bounded")

    def __init__(self, contact: bool):
        self.contact = contact
        #: The switch's searches: ``(target, g, b, noise, row)``, in the opener's order.
        self.terminal: list = []
        #: ``(target, g, noise)`` of those taken as zero at a phase start whose rate said the side:
        #: the switch may also be where one leaves rounding on the switch's side (:meth:`run`).
        self.emerging: tuple = ()  # a tuple: no allocation at every bracket's opening (nearly all)
        #: The searches ``(g, b, noise, row)`` (``_fall_search``) of the maxima of ``p`` and, in
        #: contact, of the peaks of ``delta``; None where the function keeps one strict sign.
        self.maxima: tuple | None = None
        self.peaks: tuple | None = None
        #: Normalised time up to which no search has a root (shown so far; a move that ends
        #: ``DEFER_MARGIN`` before it needs no test).
        self.clear = 0.0
        #: The shortest span whose test failed (1: the bracket's end, never shown clear).
        self.fail = 1.0
        #: ``(coefficients as a list, noise)`` of every search, made at the first test.
        self.bounded: list | None = None

    def clear_until(self, s_stop: float) -> bool:
        """Whether no search has a root in ``(0, s_stop]``, shown as in the class's text. A bracket
        that many short moves use is shown clear ahead of them: each test also tries twice the span
        shown so far (no further than halfway to the shortest span that failed), so a few tests
        cover all its moves."""
        s = s_stop + DEFER_MARGIN
        if s <= self.clear:
            return True
        if s >= self.fail:
            return False
        if self.bounded is None:
            self.bounded = [(g.tolist(), noise) for _, g, _, noise, _ in self.terminal]
            if self.maxima is not None:
                self.bounded.append((self.maxima[0].tolist(), self.maxima[2]))
        ahead = min(2.0 * self.clear, 0.5 * (self.clear + self.fail))
        for trial in ((ahead, s) if s < ahead else (s,)):
            if all(_clear(a, noise, trial) for a, noise in self.bounded):
                self.clear = trial
                return True
            self.fail = trial
        return False

    def run(self, br: "Bracket") -> None:
        """Run the searches: the first root of the switch's functions (the earlier target on a
        tie), then the non-terminal events up to it, in order."""
        direction = -1 if self.contact else +1  # a contact ends as delta falls through zero
        for target, g, b, noise, row in self.terminal:
            roots = crossings(g, direction, b, noise, row)
            if roots and roots[0] < br.s_switch:
                br.s_switch, br.switch_to = roots[0], target
        # A function taken as zero at a phase start whose rate leaves it the other way (the rate's
        # sign decides the start) but turns back within rounding is never read on that side: no
        # crossing to find, and the switch would be missed (a body leaving a barrier at 1e-13 m/s
        # that the barrier catches passed through it). It switches where it last leaves its
        # rounding level before it first passes EMERGE times it (a hump within that is a graze).
        for target, g, noise in self.emerging:
            clear = crossings(_level(g, direction * EMERGE * noise), direction)
            roots = [r for r in crossings(_level(g, direction * noise), direction) if clear and r <= clear[0]]
            if roots and roots[-1] < br.s_switch:
                br.s_switch, br.switch_to = roots[-1], target
        events = [] if self.maxima is None else [(s, MAXIMUM) for s in crossings(self.maxima[0], -1, *self.maxima[1:])
                                                 if s <= br.s_switch]
        if self.contact:
            if self.peaks is not None:
                events += [(s, PEAK) for s in crossings(self.peaks[0], -1, *self.peaks[1:]) if s <= br.s_switch]
            events.sort()
        br.events = events
        br.deferred = None


def _clear(a: list[float], noise: float, s: float) -> bool:
    """Whether the polynomial ``a`` (power coefficients, normalised time) keeps the sign of its
    start on ``[0, s]`` so clearly that no search could report a crossing there (:class:`Searches`)."""
    reach = total = 0.0
    for coefficient in reversed(a[1:]):
        size = abs(coefficient)
        reach = reach * s + size
        total += size
    start = abs(a[0])
    return start - reach * s * (1.0 + 1e-12) > 1e-6 * (total + start) + 8.0 * noise


class BracketMaps:
    """The linear maps a bracket of one phase needs from its start state ``x``, stacked as
    columns so that one product ``x @ stacked`` gives them all:

    - the Taylor coefficients of the state (ORDER+1 rows of n);
    - the power and the Bernstein coefficients of the three event functions (``functionals``,
      with the base velocity left out of ``p'``), ORDER+1 each;
    - the power coefficients of the ledger's rates (``energy_rates``): ``u'``, ``delta'`` (zero in
      free flight) and ``K u + C u'``.
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
        #: Where the base velocity enters ``p' = u' + v``: its power coefficient of order 0, then
        #: its Bernstein row (one indexed addition instead of two on views).
        self.v_index = self.split + np.array([2 * STATE_TERMS] + list(range(8 * STATE_TERMS, 9 * STATE_TERMS)))
        #: Rows (one per event function) of ``sum_i |functional_i| max_k |terms_k[i, j]|``: with the
        #: sizes ``|x_j|`` of the start state, a bound on the state terms an event function is made of.
        self.noise_rows = (np.abs(functionals).T @ np.abs(terms).max(axis=0)).tolist()
        #: Sums of those rows: times the sum of the ``|x_j|``, a bound on the rounding level.
        self.noise_bounds = [sum(row) for row in self.noise_rows]
        #: The largest column sum of ``|stacked|``: times the sum of the ``|x_j|``, a bound on the
        #: size of everything a bracket is made of.
        self.size_bound = float(np.abs(self.stacked).sum(axis=0).max())

    def mirrored(self, phase: LinearPhase, signs: np.ndarray) -> "BracketMaps":
        """The maps of the other barrier: its phase is this one's mirrored by ``signs``
        (``LinearPhase.mirrored``), and its event functions ``delta`` and ``delta'`` are this one's
        in the mirrored state, negated (``event_functionals``); the rates are the same."""
        mirror = object.__new__(BracketMaps)
        mirror.phase, mirror.split, mirror.noise_rows, mirror.noise_bounds = phase, self.split, self.noise_rows, self.noise_bounds
        mirror.size_bound, mirror.v_index = self.size_bound, self.v_index
        mirror.stacked = self.stacked * signs[:, None] * mirror_rows(len(signs))
        return mirror


@lru_cache(maxsize=None)
def mirror_rows(n: int) -> np.ndarray:
    """The column signs of ``BracketMaps.stacked`` between the barriers, for states of size ``n``:
    the state's terms like the state, ``delta`` and ``delta'`` negated, ``p'`` and the rates kept."""
    events = np.repeat([-1.0, -1.0, 1.0], STATE_TERMS)
    rows = np.concatenate([np.tile(mirror_signs(n), STATE_TERMS), events, np.ones(3 * STATE_TERMS), events])
    rows.flags.writeable = False
    return rows


def rounding(row: list[float], sizes: list[float]) -> float:
    """The rounding level of an event function: ``NOISE_ULPS`` ulp of the bound on its terms
    made from one row of ``BracketMaps.noise_rows`` and the sizes of the start state."""
    return NOISE_ULPS * EPS * sum(map(operator.mul, row, sizes))


class StateOverflow(ArithmeticError):
    """The terms of a new bracket would leave double range (the caller says which state did it)."""


class BracketOpener:
    """Opens the brackets of one damper: its maps per phase, the size under which an event
    function at a bracket start counts as zero (m), and the main spring and damper (``K`` N/m,
    ``C`` N s/m), which decide the side of a body at rest on a barrier."""

    def __init__(self, maps: dict[int, BracketMaps], zero: float, K: float, C: float):
        self.maps, self.zero, self.K, self.C = maps, zero, K, C

    def open(self, side: int, xs: list[float], t: float, y: float, v: float) -> Bracket:
        """A new bracket of phase ``side`` from the deviation state ``xs`` at time ``t`` (s), with
        the base at ``y`` (m) moving at ``v`` (m/s), with its switch and its events on it located
        (all but the circuit's voltage peaks; in free flight put off, :attr:`Bracket.deferred`).
        Raises :class:`StateOverflow`."""
        maps = self.maps[side]
        phase = maps.phase
        sizes = list(map(abs, xs))
        total = sum(sizes)  # NaN and inf propagate through it
        if not total * maps.size_bound < STATE_LIMIT:
            # Root isolation would halve NaN coefficients down to 2**-40: refuse instead.
            raise StateOverflow
        # One product gives the Taylor coefficients of the state, and the power and Bernstein
        # coefficients of the event functions (rows; the base velocity enters p' = u' + v below).
        z = np.array(xs) @ maps.stacked
        if v != 0.0:
            z[maps.v_index] += v  # G[2, 0] and B[2] below
        functions = z[maps.split:].reshape(9, STATE_TERMS)  # event functions, rates, Bernstein rows
        c, G, rates, B = z[:maps.split].reshape(STATE_TERMS, -1), functions[:3], functions[3:6], functions[6:]
        br = Bracket(c=c, t_start=t, tau=phase.h, base=y, v=v, rates=rates)
        # The rounding level of each event function: a few ulp of the largest state terms that
        # make it up, bounded from the start state (made only for the functions that need it).
        noise_rows = maps.noise_rows
        n_terminal = 2 if side == FREE else 1
        direction = +1 if side == FREE else -1
        targets = (RIGHT, LEFT) if side == FREE else (FREE,)
        values = B.tolist()
        searches = Searches(side != FREE)
        for j in range(n_terminal):
            g, b, row = G[j], B[j], values[j]
            start_value = row[0]  # the first Bernstein coefficient is the value at the start
            near_zero = abs(start_value) <= max(self.zero, NOISE_ULPS * EPS * maps.noise_bounds[j] * total)
            if not near_zero and _one_strict_sign(row):
                continue  # one strict sign, away from zero at the start: no root
            noise = rounding(noise_rows[j], sizes)
            if near_zero and abs(start_value) <= max(self.zero, noise):
                # At a switch the function that fired is zero to rounding: its sign just after
                # the start is that of the relative velocity towards the barrier. When that is
                # zero to rounding too (a body coming to rest on a barrier), the relative
                # acceleration without the barrier's force decides. Both tests read the same
                # state the same way in either phase, so the phases cannot hand over to each
                # other forever at one instant.
                barrier = targets[j] if side == FREE else side
                rate = barrier * (xs[DW] - xs[DU])
                by_rate = abs(rate) > NOISE_ULPS * EPS * (sizes[DW] + sizes[DU])
                if by_rate:
                    start = 1 if rate > 0.0 else -1
                else:
                    start = approach_sign(self.K, self.C, xs[0], xs[DU], barrier)
                if start == direction:
                    br.s_switch, br.switch_to = 0.0, targets[j]
                    return br
                # The start value set to zero: every Bernstein coefficient holds it with weight 1.
                # Most often the rest then has one strict sign (rounding is monotonic, so the
                # extremes of the shifted coefficients are the shifted extremes): away, no root.
                low, high = min(row[1:]) - start_value, max(row[1:]) - start_value
                if (low > 0.0 and direction < 0) or (high < 0.0 and direction > 0):
                    continue
                g = g.copy()
                g[0] = 0.0
                b = b - start_value
                row = [value - start_value for value in row]
                if by_rate:  # a rate that may turn back unseen (a function at rest is rounding)
                    searches.emerging += ((targets[j], g, noise),)
            searches.terminal.append((targets[j], g, b, noise, row))
        # Non-terminal events before the switch: maxima of p and, in contact, peaks of delta.
        searches.maxima = _fall_search(G, B, values, 2, sizes, noise_rows, v)
        if side != FREE:
            br.delta = G[0]
            searches.peaks = _fall_search(G, B, values, 1, sizes, noise_rows, v)
        if DEFER and side == FREE:
            if searches.terminal or searches.maxima:
                br.deferred = searches  # run once a move may reach a root (Bracket.located_to)
        else:
            searches.run(br)
        return br


def _level(g: np.ndarray, value: float) -> np.ndarray:
    """The power coefficients of ``g - value``."""
    shifted = g.copy()
    shifted[0] -= value
    return shifted


def _one_strict_sign(row: list[float]) -> bool:
    """``min(row) > 0 or max(row) < 0`` for finite values (a bracket's are: ``StateOverflow``), in
    one pass: the first value's sign says which extreme can decide."""
    first = row[0]
    if first > 0.0:
        return min(row) > 0.0
    if first < 0.0:
        return max(row) < 0.0
    return False


def _fall_search(G: np.ndarray, B: np.ndarray, values: list, j: int, sizes: list[float], noise_rows: list,
                 v: float) -> tuple | None:
    """The search of where event function ``j`` falls through zero, ``(g, b, noise, row)``: maxima
    of ``p`` (j = 2, where the base velocity adds to the rounding level) and peaks of ``delta`` (j = 1,
    in contact); None when the function keeps one strict sign on the bracket."""
    row = values[j]
    if _one_strict_sign(row):
        return None
    noise = rounding(noise_rows[j], sizes) + (NOISE_ULPS * EPS * abs(v) if j == 2 else 0.0)
    return G[j], B[j], noise, row
