"""Where the next phase switch of each trajectory lies: rigorous, vectorised event location.

A switch is the first zero of an event function ``g`` (negative while the phase lasts): in free
flight the impact mass's distance beyond a barrier, ``+-(w - u) - d/2`` (the contact onsets,
right and left); in contact the deflection turned over, ``-delta`` (the separation). With a bound
``B >= |g''|`` that holds from the present instant on (:mod:`.phases`), ``g`` stays below
``g(t) + g'(t) dt + B dt^2 / 2`` over the next ``dt``, so it has no zero before the first root
``dt`` of that parabola: stepping by it never jumps over a switch, however grazing. Near a simple
zero the steps converge quadratically (it is Newton's step from the safe side); near a tangency
they shrink geometrically and pass it. A zero is taken when ``g`` is within rounding of 0
(``NOISE_ULPS`` ulp of the quantities it is made of) while moving outwards; a touch within
rounding while moving inwards is not a switch, as in the scalar core (``piezo_fmu.solver.roots``).

**At the start of a phase** (after a switch, or at a hold step where the impact mass sits on a
barrier to rounding) the function is zero and its sign just after is that of the relative velocity
towards the barrier, or, when that is zero to rounding too, of the relative acceleration without
the barrier's force (:func:`piezo_fmu.model.dynamics.approach_sign`): the scalar core's rule
(``piezo_fmu.solver.brackets``), so that both codes decide grazing contacts alike.
"""

from __future__ import annotations

import math

#: Rounding level of an event function, in ulp of the sizes it is made of (the scalar core's).
NOISE_ULPS = 64
EPS = 2.0**-52
#: Size under which an event function at a phase start is zero, relative to the gap (the core's).
ZERO = 1e-13
#: Safe steps per phase segment before the location is declared failed: a simple zero is reached
#: in 3 to 6, a tangency to rounding passed in about 60, but a contact that rests on its barrier
#: (a light impact mass landing slowly on a stiff barrier under a slow drive) keeps its function
#: within a few 1e-11 m of zero for a whole hold step, and is proved to stay there in steps of
#: ``sqrt(2 |g| / B)``: up to 2,390 of them for one search in dampers met (200 set such trajectories
#: aside). The cap stops a search that cannot advance (a step below the rounding of ``t``): some 30 ms
#: of the compiled kernel.
MAX_ITERATIONS = 1_000_000


def safe_step(xp, g, dg, bound):
    """The first positive root ``dt`` of ``g + dg dt + bound dt^2 / 2`` for ``g <= 0`` (inf when
    there is none): no zero of the event function lies before it."""
    disc = xp.sqrt(xp.maximum(dg * dg - 2.0 * bound * g, 0.0))
    rising = dg > 0.0
    with_bound = xp.where(bound > 0.0, (disc - dg) / xp.where(bound > 0.0, bound, 1.0), math.inf)
    return xp.where(rising, -2.0 * g / xp.where(rising, dg + disc, 1.0), with_bound)


def start_sign(xp, rate, rate_noise, K: float, C: float, u, du, barrier):
    """Where the impact mass goes just after a phase start on ``barrier`` (+1 right, -1 left,
    per element): +1 into the barrier, -1 away (see the module's text)."""
    return xp.where(xp.abs(rate) > rate_noise, xp.sign(rate), xp.sign(barrier * (K * u + C * du)))


def locate(xp, evaluate, g0, dg0, tol0, near, remaining, bounds):
    """The first zero of each trajectory's event functions, from its phase start on, within
    ``remaining``.

    Parameters
    ----------
    evaluate : callable
        ``t -> (g, dg, tol)``: the event functions of the trajectories at the times ``t`` (s from
        the phase start, one per trajectory): arrays (k, L) for the ``k`` functions, their rates,
        and their rounding level (L,).
    g0, dg0 : (k, L) arrays
        The functions and their rates at the start; ``tol0`` (L,) their rounding level.
    near : (k, L) bool
        Functions zero at the start (to rounding) that head inwards: their start value is taken as
        0, and they do not fire at the start.
    remaining : (L,) array
        s left in the hold step.
    bounds : (L,) array
        ``B >= |g''|`` from the start on, for every function of a trajectory.

    Returns
    -------
    (time, which, failed)
        ``time`` (L,): s from the start to the first zero, inf when none lies within ``remaining``;
        ``which`` (L,): the index of the function that fires; ``failed`` (L,): the location did not
        converge within ``MAX_ITERATIONS`` or met a value that is not finite (the caller sets such
        a trajectory aside).

    The trajectories are few (those that may switch in a step), so every iteration works on all of
    them, the finished ones held where they stopped.
    """
    k, L = g0.shape
    time = xp.full((L,), math.inf)
    which = xp.zeros((L,), dtype=xp.int64)
    failed = xp.zeros((L,), dtype=xp.bool)
    active = xp.ones((L,), dtype=xp.bool)
    g, dg, tol, held = xp.where(near, 0.0, g0), dg0, tol0, near
    t = xp.zeros((L,))
    for _ in range(MAX_ITERATIONS):
        fired = (g >= -tol) & (dg > 0.0) & ~held
        hit = xp.any(fired, axis=0) & active
        # A function within rounding of 0 that does not fire (a touch heading inwards, or a start
        # value taken as 0 with no rate) steps on from just below zero.
        stalled = (g >= -tol) & ~fired
        after = t + xp.min(safe_step(xp, xp.where(stalled, -tol, xp.minimum(g, 0.0)), dg, bounds), axis=0)
        past = active & ~hit & (after >= remaining)
        bad = active & ~hit & ~past & ~xp.isfinite(after)
        time = xp.where(hit, t, time)
        which = xp.where(hit, xp.argmax(xp.astype(fired, xp.int64), axis=0), which)
        failed = failed | bad
        active = active & ~(hit | past | bad)
        if not bool(xp.any(active)):
            return time, which, failed
        t = xp.where(active, after, t)
        g, dg, tol = evaluate(t)
        held = xp.zeros(g.shape, dtype=xp.bool)
    return time, which, failed | active
