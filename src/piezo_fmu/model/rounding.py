"""The rounding levels at which the model's switches are decided, and the switch limit: one home
for the numbers that the scalar core (:mod:`piezo_fmu.solver`), the compiled kernel of the batch
engine (:mod:`piezo_fmu.solver.batch.kernel`) and Model Exchange (:mod:`piezo_fmu.fmi.me_run`)
decide by, so that all three decide a grazing contact, a body at rest on a barrier or a switch at a
phase start alike (docs/model.md section 3).
"""

#: The spacing of float64 at 1 (machine epsilon).
EPS = 2.0**-52
#: The rounding level of an event function, in ulp of the sizes of the terms it is made of: a value
#: within it is zero, and a rate within it of the velocities it is made of is no rate.
NOISE_ULPS = 64
#: The size, relative to the gap ``d``, under which an event function at a phase start is zero
#: whatever its rounding level.
ZERO = 1e-13
#: Phase switches of one body at one instant before a run is declared degenerate.
MAX_SWITCHES_AT_ONE_INSTANT = 8
