"""Many trajectories of one damper, each under a base input of its own, marched together on the
compiled kernel (:mod:`.kernel.inputs`): what a study of random base excitation marches.

The base of each trajectory is a first-order hold of step ``h``, as an FMU fed
``base_displacement`` and ``base_velocity`` at each communication step's start holds it: the
nodes ``y_k`` (m) and the slopes ``v_k = (y_{k+1} - y_k) / h`` (m/s). :meth:`InputEnsemble.advance`
takes a block of them, ``(n, B + 1)`` nodes and ``(n, B)`` slopes (a trajectory's a row), and returns
the main mass's position at each step's end; meanwhile each trajectory accumulates, step by step,
the sums and largest values of its motion (:attr:`InputEnsemble.stats`), its contact onsets
(:attr:`InputEnsemble.counts`) and its energy flows (:attr:`InputEnsemble.ledger`, docs/model.md
section 5.7), from the start or from the last :meth:`InputEnsemble.restart_accounts`.
:meth:`InputEnsemble.energy` gives the energy stored in each trajectory, so that the ledger's balance
can be checked: the base's work equals the stored energy's change, the dissipation, the plastic
losses and the harvested energy.

A trajectory gives the same bits alone and in a batch, and in any cut of its input into blocks:
its motion and its accounts.
"""

from __future__ import annotations

import numpy as np

from ...model.parameters import Parameters
from . import kernel
from .ensemble import checked_states
from .model import BatchModel


class InputEnsemble:
    """``n`` trajectories of the damper ``params`` (its initial-state fields unused), each under a
    base input of its own of step ``step`` (s), from ``states`` ((n, 4): ``p, p', q, q'``, m and m/s,
    at ``t = 0``), ``sides`` (0 free, the default, or +-1 in contact) and, under ``voltage_model = 2``,
    the patch voltages ``volts`` ((2, n), V; 0 by default), on ``device`` ("cpu" or "gpu")."""

    def __init__(self, params: Parameters, step: float, states, sides=None, volts=None, device: str = "cpu",
                 model: BatchModel | None = None):
        if error := kernel.device_error(device):
            raise ValueError(error)
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"step = {step!r} s is out of range; allowed range (0, inf)")
        self.params, self.model, self.device = params, model or BatchModel.of(params), device
        states, sides, volts = checked_states(params, self.model, states, sides, volts)
        self.n = n = len(states)
        self._tables = kernel.Tables(self.model, [])
        self._hold = kernel.input_hold(self.model, step)
        self.step = float(step)
        self._state = np.empty((7, n))
        self._state[:4], self._state[4], self._state[5:] = states.T, sides, volts
        self.failed = np.zeros(n, dtype=bool)
        self.steps = 0
        self.restart_accounts()

    def restart_accounts(self) -> None:
        """Start the accounts afresh from the present instant (after a warm-up, say)."""
        self._accounts = kernel.accumulators(self.n)

    @property
    def stats(self) -> np.ndarray:
        """(n, 4): each trajectory's sums of ``(p - y)^2`` and ``p^2`` (m^2) at the steps' ends, and its
        largest ``|p - y|`` and ``|p|`` (m, of the Hermite interpolant of each step's ends), since
        the accounts started (:data:`STATS` names them); NaN for a failed trajectory."""
        return self._accounts[0].copy()

    @property
    def counts(self) -> np.ndarray:
        """(n,): each trajectory's contact onsets since the accounts started."""
        return self._accounts[1].copy()

    @property
    def ledger(self) -> np.ndarray:
        """(n, 6), J: each trajectory's energy flows since the accounts started (:data:`LEDGER` names
        them): the base's work, the main damper's and the barrier's dissipation, the plastic losses,
        the energy into the left and right loads."""
        return self._accounts[2].copy()

    @property
    def states(self) -> np.ndarray:
        """``(p, p', q, q')`` of every trajectory now, (n, 4)."""
        return np.ascontiguousarray(self._state[:4].T)

    @property
    def sides(self) -> np.ndarray:
        """The phase of every trajectory now: 0 free, +1 or -1 in contact with that barrier."""
        return self._state[4].astype(np.int64)

    @property
    def voltages(self) -> np.ndarray:
        """The patch voltages (V) now, (2, n): left, right (0 unless ``voltage_model = 2``)."""
        return self._state[5:].copy()

    def advance(self, nodes, slopes, onsets: bool = False):
        """March every trajectory through a block of its input: ``nodes`` ((n, B + 1), m; the first
        column where the last block ended) and ``slopes`` ((n, B), m/s). Returns ``p`` (m) at each
        step's end, (n, B), and with ``onsets`` also the contact onsets in each step, (n, B). A
        trajectory whose events could not be located is NaN from then on and flagged in
        :attr:`failed`."""
        nodes, slopes = np.asarray(nodes, float), np.asarray(slopes, float)
        if slopes.ndim != 2 or slopes.shape[0] != self.n or slopes.shape[1] < 1 \
                or nodes.shape != (self.n, slopes.shape[1] + 1):
            raise ValueError(f"nodes {nodes.shape} and slopes {slopes.shape}: allowed shapes ({self.n}, B + 1) and "
                             f"({self.n}, B), B >= 1 steps")
        positions, counts = kernel.march_input(self.device, self._tables, self._hold, self._state, self.failed,
                                               self._accounts, nodes, slopes)
        self.steps += slopes.shape[1]
        return (positions, counts) if onsets else positions

    def energy(self, y) -> np.ndarray:
        """The energy stored (J) in each trajectory now, with the base at ``y`` ((n,), m): kinetic,
        the main spring's, the barrier's in contact, and the patches' (docs/model.md section 5.7)."""
        model = self.model
        p, dp, q, dq, side, vl, vr = self._state
        contact = side != 0.0
        deflection = np.where(contact, side * (q - p) - model.half_gap, 0.0)
        kinetic = np.where(contact, model.M1 * dp**2 + (model.m + model.M_eq) * dq**2, model.M * dp**2 + model.m * dq**2)
        return 0.5 * (kinetic + model.K * (p - np.asarray(y, float))**2 + model.K_eq * deflection**2
                      + model.C_p * (vl**2 + vr**2))


#: The columns of :meth:`InputEnsemble.advance`'s ``stats`` and ``ledger``.
STATS = ("squares_relative", "squares_absolute", "largest_relative", "largest_absolute")
LEDGER = ("work_base", "dissipated_C", "dissipated_Ceq", "plastic", "harvested_left", "harvested_right")
