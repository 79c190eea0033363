"""The energy ledger: the energy flows of a run, integrated exactly bracket by bracket.

Dissipation in ``C`` and ``C_eq`` and the work of the base are integrals of the bracket
polynomials of the rates (:func:`piezo_fmu.model.energy.energy_rates`). A closed bracket is booked
in batches of ``BATCH``, as quadratic forms with the Hilbert matrix; the open bracket is read from
the primitives of its rates. The plastic losses of the switches and the work of jumps of the base
displacement are booked as they happen.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .brackets import Bracket
from .propagation import PRIMITIVE_TERMS, STATE_TERMS, primitive, primitive_of_square

#: ``1 / (j + k + 1)``: the integrals over [0, 1] of products of powers (:func:`ledger_integrals`).
_HILBERT = 1.0 / (np.arange(STATE_TERMS)[:, None] + np.arange(STATE_TERMS)[None, :] + 1.0)
#: Closed brackets whose ledger is booked in one set of products (:meth:`Ledger.book_pending`).
BATCH = 64
#: The accumulated flows, in the order of a snapshot's "accounts".
ACCOUNTS = ("dissipated_C", "dissipated_Ceq", "plastic", "work_base", "initial")


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
        return self.totals()[2]

    @property
    def electrical_balance_error(self) -> float:
        """``electrical + harvested - converted``, J: the circuit's own balance, zero for exact bookkeeping."""
        return self.electrical + self.harvested - self.converted

    @property
    def dissipated(self) -> float:
        """All energy dissipated so far, J."""
        return self.totals()[0]

    @property
    def balance_error(self) -> float:
        """``total - (initial + work_base - dissipated - electrical_work)``, J: zero for exact bookkeeping."""
        return self.totals()[1]

    def totals(self) -> tuple[float, float, float]:
        """:attr:`dissipated`, :attr:`balance_error` and :attr:`harvested` (J), at once (a host that
        reads them all at every step reads them here)."""
        kinetic, potential_K, potential_Keq, dissipated_C, dissipated_Ceq, plastic, work_base, initial, \
            _, harvested_left, harvested_right, _, electrical_work = self
        dissipated = dissipated_C + dissipated_Ceq + plastic
        balance_error = kinetic + potential_K + potential_Keq - (initial + work_base - dissipated - electrical_work)
        return dissipated, balance_error, harvested_left + harvested_right


def ledger_integrals(rates: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """For brackets stopped at ``s`` (``powers`` = ``s^k``), shape (brackets, 3): the integrals
    over ``[0, s]`` of the squares of the first two rates and of the third, divided by ``s``.

    ``int_0^s a(r)^2 dr = s (a p)^T H (a p)`` with ``p_k = s^k`` and the Hilbert matrix
    ``H_jk = 1 / (j + k + 1)``, whose first row also gives ``int_0^s a(r) dr = s H[0] (a p)``:
    the same integrals as the primitives of :meth:`Ledger.open_reading`, to rounding."""
    scaled = rates * powers[:, None, :]
    weighted = scaled @ _HILBERT
    integrals = np.add.reduce(scaled * weighted, axis=2)
    integrals[:, 2] = weighted[:, 2, 0]
    return integrals


class Ledger:
    """The accumulated energy flows of a run (J), and the closed brackets not booked yet.

    ``C`` and ``C_eq`` (N s/m) weigh the dissipation rates. The pending brackets are kept in arrays
    made once (at most ``BATCH``): the memory of a run does not grow with it.
    """

    def __init__(self, C: float, C_eq: float):
        self.C, self.C_eq = C, C_eq
        self.dissipated_C = self.dissipated_Ceq = self.plastic = self.work_base = self.initial = 0.0
        self._rates = np.empty((BATCH, 3, STATE_TERMS))
        self._powers = np.empty((BATCH, STATE_TERMS))
        self._span = np.empty(BATCH)
        self._v = np.empty(BATCH)
        self._count = 0

    def factors(self, span, v):
        """Factors of the ledger's rates: ``C``, ``C_eq`` and ``-v``, times ``span``, the time the
        bracket has run (the rates are polynomials in normalised time; :func:`ledger_integrals`).
        Floats for one bracket, arrays for a batch."""
        return self.C * span, self.C_eq * span, -v * span

    def close(self, br: Bracket) -> None:
        """Take the bracket ``br``, closed where its state stands, for booking."""
        i = self._count
        self._rates[i] = br.rates
        self._powers[i] = br.powers[:STATE_TERMS]
        self._span[i] = br.tau * br.s  # s, normalised, times the bracket's length
        self._v[i] = br.v
        self._count = i + 1
        if i + 1 == BATCH:
            self.book_pending()

    def book_pending(self) -> None:
        """Book the closed brackets not booked yet, in one set of products: the same whether a
        host read the ledger in between or not, to rounding."""
        n = self._count
        if not n:
            return
        integrals = ledger_integrals(self._rates[:n], self._powers[:n])
        factors = self.factors(self._span[:n], self._v[:n])
        booked = [(integrals[:, k] * factors[k]).tolist() for k in range(3)]
        self.dissipated_C += math.fsum(booked[0])
        self.dissipated_Ceq += math.fsum(booked[1])
        self.work_base += math.fsum(booked[2])
        self._count = 0

    def open_reading(self, br: Bracket) -> list[float]:
        """Dissipation in ``C`` and ``C_eq`` and work of the base (J) on the open bracket so far,
        read from the primitives of the rates (made on the first reading of the bracket: a host
        that reads the ledger every step pays one product per reading)."""
        if br.ledger is None:
            u_rate, delta_rate, force = br.rates
            weights = self.factors(br.tau, br.v)
            br.ledger = np.zeros((3, PRIMITIVE_TERMS))
            primitive_of_square(u_rate, weights[0], out=br.ledger[0])
            primitive_of_square(delta_rate, weights[1], out=br.ledger[1])
            primitive(force, weights[2], out=br.ledger[2])
        return br.ledger.dot(br.powers).tolist()

    def booked(self, br: Bracket) -> tuple[float, float, float]:
        """What closing the bracket now would book (:meth:`book_pending`)."""
        squares = ledger_integrals(br.rates[None], br.powers[None, :STATE_TERMS])[0].tolist()
        weights = self.factors(br.tau * br.s, br.v)
        return weights[0] * squares[0], weights[1] * squares[1], weights[2] * squares[2]

    def flows(self, br: Bracket | None) -> tuple[float, float, float, float]:
        """``dissipated_C``, ``dissipated_Ceq``, ``plastic`` and ``work_base`` (J) so far, the open
        bracket ``br`` (if any) included."""
        if self._count:
            self.book_pending()
        open_C, open_Ceq, open_base = self.open_reading(br) if br is not None else (0.0, 0.0, 0.0)
        return self.dissipated_C + open_C, self.dissipated_Ceq + open_Ceq, self.plastic, self.work_base + open_base

    def to_dict(self) -> dict:
        """The accumulated flows (after booking every closed bracket), JSON-safe."""
        self.book_pending()
        return {name: getattr(self, name) for name in ACCOUNTS}

    def restore(self, accounts: dict) -> None:
        """Set the accumulated flows saved by :meth:`to_dict`."""
        for name in ACCOUNTS:
            setattr(self, name, float(accounts[name]))
