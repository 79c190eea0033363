"""Where starts go, on the batch engine: each start marched until its own trajectory shows the
motion it reaches (:func:`settle`), the periodic orbits that Newton finds and verifies on the
engine (:mod:`.orbits`), the measures of a motion that is not periodic (:mod:`.measures`), and the
bookkeeping between two blocks of marching, compiled with the kernel (:mod:`.books`).

A start's label is the index of the attractor it reaches, or :data:`UNDECIDED` when the budget of
periods did not resolve it, :data:`SET_ASIDE` when the engine could not locate its events.
"""

from .measures import tracks
from .settle import SET_ASIDE, UNDECIDED, SettleSettings, Settled, describe, settle

__all__ = ["SET_ASIDE", "SettleSettings", "Settled", "UNDECIDED", "describe", "settle", "tracks"]
