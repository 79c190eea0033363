"""The layout of the arrays the kernel reads: the damper's constants ``c``, a trajectory's scratch row
``work`` and a drive's row of ``drive`` (filled by :class:`.tables.Tables`).

``c`` holds the free flight's and the switch rules' numbers, then the contact's modes, padded to
:data:`MODES` (a padded mode has a zero amplitude: it adds exact zeros): eigenvalues, ``|lam|^2``,
gains, ``Q^-1`` and ``Q``, real parts then imaginary parts, matrices row by row, each mode's weight
and the number of modes used. A complex pair of modes is carried once, with weight 2: the state is
real, so its two terms are each other's conjugates and their sum is twice the real part of one; a
real mode has weight 1.
"""

#: Offsets into ``c``: ``a = C / 2M`` (1/s), ``w_n^2`` (1/s^2), ``a^2 - w_n^2`` (1/s^2), the kind of
#: free flight (:data:`CRITICAL`, :data:`UNDERDAMPED`, :data:`OVERDAMPED`), the damped frequency or
#: decay rate (1/s), ``w_n + 2a`` (1/s), ``d/2`` (m), ``M``, ``M - M_eq``, ``m``, ``M_eq`` (kg), ``K``
#: (N/m), ``C`` (N.s/m), 1.0 when the circuit acts back on the contact, ``R C_p`` (s), the barrier's
#: ``K_eq`` (N/m) and ``C_eq`` (N.s/m), the load ``R`` (Ohm).
A, W2, BETA2, CS_MODE, WD, BOUND_RATE, HG, MM, M1, MI, M_EQ, KK, CC, COUPLED, TAU_E, K_EQ, C_EQ, R_LOAD = range(18)
#: The kinds of free flight: critical damping (series), underdamped (cos, sin), overdamped (cosh, sinh).
CRITICAL, UNDERDAMPED, OVERDAMPED = 0.0, 1.0, 2.0
#: Contact modes carried (4 states, or 5 with the voltage under ``voltage_model = 2``).
MODES = 5
LAM = 18
LAM2 = LAM + 2 * MODES
GAIN = LAM2 + MODES
QINV = GAIN + 2 * MODES
QM = QINV + 2 * MODES * MODES
WEIGHT = QM + 2 * MODES * MODES
USED = WEIGHT + MODES
CONSTANTS = USED + 1

#: Offsets into ``work``, the scratch floats of one trajectory: the contact's modal amplitudes alpha
#: and ``alpha * gain`` (re, im), then the last evaluation of each phase's event function, kept for
#: the step to a located switch (the same numbers, not computed twice): the modes' ``e^{lam t}``
#: (re, im) at the time ``CONTACT_AT``, and free flight's coefficients at ``FREE_AT``.
GROWTH = 4 * MODES
CONTACT_AT = 6 * MODES
FREE_AT, FREE_EC, FREE_ES = CONTACT_AT + 1, CONTACT_AT + 2, CONTACT_AT + 3
WORK = CONTACT_AT + 4

#: Offsets into a row of ``drive``: the hold step (s), ``e^{-a h} c(h)``, ``e^{-a h} s(h)``, the
#: voltage's decay over a step, then the ``N + 1`` node values (m) and the ``N`` slopes (m/s).
STEP, EC, ES, DECAY, NODES = range(5)

#: Offsets into a row of ``hold``, the constants of the one hold step of a march under a given base
#: input (:func:`.tables.input_hold`): the step (s), ``e^{-a h} c(h)``, ``e^{-a h} s(h)``, the
#: voltage's decay, then free flight's integrals over the step: ``int c``, ``int s`` (s) and
#: ``int c^2``, ``int c s``, ``int s^2`` (s) of ``c(t) = e^{-a t} c(t)``, ``s(t) = e^{-a t} s(t)``,
#: and ``int e^{-2 t / (R C_p)} dt / R`` (s/Ohm: a decaying patch's energy into its load per V^2).
H_STEP, H_EC, H_ES, H_DECAY, H_C, H_S, H_CC, H_CS, H_SS, H_LOAD = range(10)
HOLD = 10

#: Offsets into a trajectory's row of ``ledger``, the energy flows (J) it accumulates: the work of
#: the base, the main damper's and the barrier's dissipation, the plastic losses at the switches, the
#: energy harvested in the left and right loads.
L_WORK, L_C, L_CEQ, L_PLASTIC, L_LEFT, L_RIGHT = range(6)
LEDGER = 6
#: Offsets into a trajectory's row of ``stats``, what it accumulates of its motion over a block:
#: the sums of ``(p - y)^2`` and ``p^2`` (m^2) at the end of each step, and the largest ``|p - y|``
#: and ``|p|`` (m) over the steps (the Hermite interpolant of each step's ends).
S_U2, S_P2, S_UMAX, S_PMAX = range(4)
STATS = 4
