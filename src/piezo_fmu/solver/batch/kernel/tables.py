"""A damper and its drives packed for the kernel: the arrays ``c`` and ``drive`` (:mod:`.layout`)."""

from __future__ import annotations

import math

import numpy as np

from ..model import BatchModel
from . import layout as at


class Tables:
    """A damper (``model``) and its drives (``drives``: :class:`..drive.HarmonicHold` objects with the
    same number of nodes a period, none for a march under base inputs of its own) packed for the
    kernel: ``constants`` (the array ``c``) and ``drive`` (one row a drive), host arrays."""

    def __init__(self, model: BatchModel, drives: list):
        free, contact = model.free, model.contact
        if abs(free.beta2) <= 1e-12 * free.w2:
            mode, wd = at.CRITICAL, 0.0
        elif free.beta2 < 0.0:
            mode, wd = at.UNDERDAMPED, math.sqrt(-free.beta2)
        else:
            mode, wd = at.OVERDAMPED, math.sqrt(free.beta2)
        values = {at.A: free.a, at.W2: free.w2, at.BETA2: free.beta2, at.CS_MODE: mode, at.WD: wd,
                  at.BOUND_RATE: free.bound_rate, at.HG: model.half_gap, at.MM: model.M, at.M1: model.M1,
                  at.MI: model.m, at.M_EQ: model.M_eq, at.KK: model.K, at.CC: model.C,
                  at.COUPLED: 1.0 if model.coupled else 0.0, at.TAU_E: model.tau_e, at.K_EQ: model.K_eq,
                  at.C_EQ: model.C_eq, at.R_LOAD: model.params.R_load}
        n, modes = contact.size, at.MODES
        used, weight = _modes(contact.lam)
        lam, lam2, gain = np.zeros(modes, complex), np.zeros(modes), np.zeros(modes, complex)
        qinv, qm = np.zeros((modes, modes), complex), np.zeros((modes, modes), complex)
        k = len(used)
        lam[:k], lam2[:k], gain[:k] = contact.lam[used], np.abs(contact.lam[used]) ** 2, contact.gain[used]
        qinv[:k, :n], qm[:n, :k] = contact.Q_inv[used, :], contact.Q[:, used]
        weights = np.zeros(modes)
        weights[:k] = weight
        parts = lambda z: [z.real.ravel(), z.imag.ravel()]  # noqa: E731
        self.constants = np.concatenate([[values[k] for k in range(at.LAM)], *parts(lam), lam2, *parts(gain),
                                         *parts(qinv), *parts(qm), weights, [float(len(used))]])
        assert self.constants.shape == (at.CONSTANTS,)
        if not drives:  # a march under base inputs of its own (:func:`input_hold`)
            self.drive = np.zeros((0, at.NODES))
            return
        h = np.array([drive.step for drive in drives])
        ec, es = free.coefficients(h)
        nodes = [drive.nodes() for drive in drives]
        self.drive = np.ascontiguousarray(np.column_stack([h, ec, es, np.exp(-h / model.tau_e),
                                                           np.stack([y for y, _ in nodes]),
                                                           np.stack([v for _, v in nodes])]))

    def arguments(self) -> tuple:
        """``(drive, c)``, as the kernel's entry points take them."""
        return self.drive, self.constants


def _modes(lam: np.ndarray) -> tuple[list, list]:
    """The contact's modes the kernel carries and their weights: each complex pair once (the one
    with the positive imaginary part, weight 2), each real mode with weight 1."""
    used, weight = [], []
    for k, value in enumerate(lam):
        if value.imag > 0.0:
            partner = np.abs(lam - np.conj(value)).argmin()
            if lam[partner].imag >= 0.0 or abs(lam[partner] - np.conj(value)) > 1e-12 * abs(value):
                raise AssertionError(f"contact: the eigenvalue {value} has no conjugate partner")
            used.append(k)
            weight.append(2.0)
        elif value.imag == 0.0:
            used.append(k)
            weight.append(1.0)
    return used, weight


def input_hold(model: BatchModel, step: float) -> np.ndarray:
    """The constants of a hold step ``step`` (s) for a march under a base input of its own
    (:mod:`.inputs`, :data:`.layout.HOLD` of them): the step, free flight's coefficients and the
    voltages' decay over it, as a drive's row has them, free flight's integrals over it (the 8-point
    Gauss-Legendre rule of :mod:`.ledger`, on as many pieces as it takes there) and a decaying
    patch's energy into its load."""
    free = model.free
    h = float(step)
    ec, es = (float(value) for value in free.coefficients(np.array(h)))
    pieces = max(1, math.ceil((math.sqrt(free.w2) + 2.0 * free.a) * h))
    x, w = np.polynomial.legendre.leggauss(8)
    width = h / pieces
    times = (np.arange(pieces)[:, None] + (x[None, :] + 1.0) / 2.0).ravel() * width
    weights = np.tile(w / 2.0, pieces) * width
    c, s = free.coefficients(times)
    hold = np.zeros(at.HOLD)
    hold[[at.H_STEP, at.H_EC, at.H_ES, at.H_DECAY]] = h, ec, es, math.exp(-h / model.tau_e)
    hold[[at.H_C, at.H_S, at.H_CC, at.H_CS, at.H_SS]] = (weights @ c, weights @ s, weights @ (c * c),
                                                         weights @ (c * s), weights @ (s * s))
    if model.coupled:  # otherwise the engine carries no voltage, and R C_p is infinite (or R 0)
        hold[at.H_LOAD] = model.tau_e * 0.5 * -math.expm1(-2.0 * h / model.tau_e) / model.params.R_load
    return hold
