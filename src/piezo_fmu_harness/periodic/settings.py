"""How one frequency's steady state is found and checked (:mod:`piezo_fmu_harness.periodic.steady_state`):
the settings of the search, shared by the studies of the forced response.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Settings:
    """How one frequency's steady state is found and checked.

    Attributes
    ----------
    samples : int
        Communication steps per forcing period (the base's nodes), >= 16.
    tolerance : float
        Steady-state tolerance on the section's return, relative to the base amplitude ``Y``.
    max_cycles : int
        Cap on the forcing cycles simulated for one frequency (Newton's evaluations, the
        stability checks and the search for a stable orbit included).
    newton_iterations : int
        Newton iterations per attempt; 0 finds the steady state by time-marching alone.
    max_order : int
        Longest period of an orbit looked for, in forcing periods.
    warmup_cycles : int
        Forcing cycles marched from the guess before the first Newton attempt (the last one
        chooses the section's phase).
    march_cycles : int
        Forcing cycles marched between Newton attempts.
    window_cycles : int
        Forcing cycles over which a motion that is not periodic is measured.
    classify_cycles : int
        Forcing cycles after the window over which such a motion is classified
        (:mod:`piezo_fmu_harness.periodic.motion`).
    """

    samples: int = 64
    tolerance: float = 1e-6
    max_cycles: int = 400
    newton_iterations: int = 12
    max_order: int = 4
    warmup_cycles: int = 2
    march_cycles: int = 8
    window_cycles: int = 60
    classify_cycles: int = 40

    #: Newton attempts per search: at its start, then after 1, 3, 7, ... blocks of marching (a
    #: transient that decays slowly, as at zeta = 0.0016, gets late attempts near its end).
    NEWTON_ATTEMPTS = 6
    #: Finite-difference step of Newton's Jacobian, relative to the state's scale.
    FD_STEP = 1e-7
    #: Returns the verification run checks, in orbits.
    VERIFY_ORBITS = 3
    #: Displacement of an unstable orbit along its unstable eigenvector, relative to its size.
    ESCAPE_STEP = 1e-2
    #: Unstable orbits the search escapes from, at most, per frequency.
    MAX_ESCAPES = 4
