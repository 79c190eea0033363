"""The full state of a :class:`~piezo_fmu.solver.simulator.Simulator`, saved and restored.

A snapshot is JSON-safe (floats, ints, lists): the phase, the open bracket, the event
bookkeeping, the ledger's accounts, the metric accumulators and, under the circuit models, the
booked circuit state. A simulator restored from it goes on bit for bit as the original would.
"""

from __future__ import annotations

from dataclasses import asdict

from ..model.dynamics import FREE
from .brackets import Bracket
from .metrics import MetricAccumulators
from .records import Impact


def snapshot_of(sim) -> dict:
    """The full internal state of ``sim`` as a JSON-safe dict."""
    data = {
        "t": sim.t, "p": sim._p, "dp": sim._dp, "q": sim._q, "dq": sim._dq,
        "side": sim._side, "y": sim._y, "v": sim._v,
        "accounts": sim._ledger.to_dict(), "metrics": sim._acc.to_dict(),
        "open": asdict(sim._open) if sim._open else None,
        "impacts": [asdict(i) for i in sim._impacts],
        "maxima": [list(m) for m in sim._maxima],
        "bracket": sim._bracket.to_dict() if sim._bracket else None,
    }
    if sim._circuit is not None:
        # The voltage on an open contact bracket is rebuilt from the bracket and the booked V.
        data["circuit"] = sim._circuit.to_dict()
    return data


def restore_into(sim, snapshot: dict) -> None:
    """Put the fresh simulator ``sim`` (of the parameters the snapshot was taken with) in the state
    saved by :func:`snapshot_of`. Raises ``ValueError`` when the snapshot's voltage model differs."""
    sim.t = float(snapshot["t"])
    sim._p, sim._dp, sim._q, sim._dq = (float(snapshot[k]) for k in ("p", "dp", "q", "dq"))
    sim._side = int(snapshot["side"])
    sim._y, sim._v = float(snapshot["y"]), float(snapshot["v"])
    sim._ledger.restore(snapshot["accounts"])
    sim._acc = MetricAccumulators.from_dict(snapshot["metrics"])
    sim._open = Impact(**snapshot["open"]) if snapshot["open"] else None
    sim._impacts.extend(Impact(**i) for i in snapshot["impacts"])
    sim._maxima.extend(tuple(m) for m in snapshot["maxima"])
    sim._bracket = Bracket.from_dict(snapshot["bracket"]) if snapshot["bracket"] else None
    circuit = sim._circuit
    if circuit is not None:
        if "circuit" not in snapshot:
            raise ValueError(f"the snapshot has no circuit state: it was saved under voltage_model = 0, "
                             f"not {sim.params.voltage_model}")
        circuit.restore(snapshot["circuit"])
        if sim._bracket is not None and sim._side != FREE:
            circuit.open(sim._bracket.c, sim._bracket.tau, sim._side)
