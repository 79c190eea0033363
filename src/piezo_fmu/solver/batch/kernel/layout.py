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
#: (N/m), ``C`` (N.s/m), 1.0 when the circuit acts back on the contact, ``R C_p`` (s).
A, W2, BETA2, CS_MODE, WD, BOUND_RATE, HG, MM, M1, MI, M_EQ, KK, CC, COUPLED, TAU_E = range(15)
#: The kinds of free flight: critical damping (series), underdamped (cos, sin), overdamped (cosh, sinh).
CRITICAL, UNDERDAMPED, OVERDAMPED = 0.0, 1.0, 2.0
#: Contact modes carried (4 states, or 5 with the voltage under ``voltage_model = 2``).
MODES = 5
LAM = 15
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
