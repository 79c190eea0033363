"""The kernel's march as one flat loop of small steps, for a GPU (issue 32): the same motion as
:func:`.kernel_source.march_one`, bit for bit, in another order of work.

**Why.** On a GPU the 32 threads of a warp execute one instruction together. ``march_one`` nests
three loops of different lengths for different trajectories: the hold steps of a period, the event
rounds of a step, the iterations of an event search. A warp then waits, in every hold step, for its
slowest thread's search: measured with Nsight Compute on an H200, 3.3 of a warp's 32 threads were
active on average, and the launch ran 15 times slower than on 1,000,000 copies of one start.

**How.** Each trajectory's work is cut into the pieces those loops are made of, and one loop runs
them: each pass does, for every trajectory, at most one hold step's start, one round's start, one
iteration of its event search (one evaluation of the event functions) and one round's end. A warp's
threads stay together at the top of the loop, whatever each has left to do; a trajectory that
finishes early waits only at the end of the launch.

**Same bits.** The pieces are the source's own functions (:func:`.kernel_phases.free_start`,
:func:`.kernel_phases.contact_start`, :func:`.kernel_phases.locate_step`,
:func:`.kernel_source.round_end`, :func:`.kernel_source.free_step`), called with the same numbers
in the same order for each trajectory: only the interleaving of trajectories differs. The tests
run both on the CPU and compare the bits.
"""

from .kernel_phases import INF, MAX_ITERATIONS, NAN, contact_start, fmax, fmin, free_start, locate_step
from .kernel_source import (DONE, FAILED, MAX_ROUNDS, NODES, STEP, EC, ES, DECAY, contact_voltage, free_step,
                            hermite_extremes, round_end, round_start)

#: What a trajectory does next: start a hold step, start a round, search, end a round, end a step.
AT_STEP, AT_ROUND, AT_SEARCH, AT_END, AT_STEP_END = range(5)


def march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work):
    """:func:`.kernel_source.march_one` (the same arguments, the same results) as one loop."""
    p, dp, q, dq, side, vl, vr = (state[0, i], state[1, i], state[2, i], state[3, i], state[4, i], state[5, i],
                                  state[6, i])
    bad = failed[i]
    g = groups[i]
    h, ec, es, decay = drive[g, STEP], drive[g, EC], drive[g, ES], drive[g, DECAY]
    samples = (drive.shape[1] - NODES - 1) // 2
    periods = sections.shape[0]
    period = k = onsets = 0
    top = bottom = p if observe and not bad else NAN
    phase = AT_STEP
    # the hold step's, the round's and the search's state
    y0 = v = p0 = dp0 = tl = 0.0
    instant = step_onsets = rounds = iterations = 0
    u = du = w = dw = rem = base = bound = s = t = g_a = g_b = dg_a = dg_b = tol = t_ev = to = 0.0
    held_a = held_b = contact = search_bad = False
    while period < periods:
        end_period = bad
        if not bad and phase == AT_STEP:
            y0, v = drive[g, NODES + k], drive[g, NODES + samples + 1 + k]
            p0, dp0 = p, dp
            step_onsets = 0
            phase = AT_ROUND
            if side == 0.0:
                p1, dp1, q1, dq1, possible = free_step(p, dp, q, dq, y0, v, h, ec, es, c)
                if not possible:
                    p, dp, q, dq, vl, vr = p1, dp1, q1, dq1, vl * decay, vr * decay
                    phase = AT_STEP_END
            tl = 0.0
            instant = rounds = 0
        if not bad and phase == AT_ROUND:
            if rounds == MAX_ROUNDS:
                bad = True
            else:
                rounds += 1
                u, du, w, dw, rem, base = round_start(p, dp, q, dq, y0, v, tl, h)
                contact = side != 0.0
                if contact:
                    now, g_a, dg_a, tol, held_a, bound = contact_start(c, u, du, w, dw, side,
                                                                       contact_voltage(side, vl, vr, c), work)
                    g_b, dg_b, held_b, to, s = -INF, 0.0, False, 0.0, side
                else:
                    now, to, g_a, g_b, dg_a, dg_b, tol, held_a, held_b, bound = free_start(c, work, u, du, w, dw)
                    s = 0.0
                if now:
                    t_ev, search_bad = 0.0, False
                    phase = AT_END
                else:
                    g_a = 0.0 if held_a else g_a
                    g_b = 0.0 if held_b else g_b
                    t = 0.0
                    iterations = 0
                    phase = AT_SEARCH
        if not bad and phase == AT_SEARCH:
            found, t_ev, which, search_bad, t, g_a, g_b, dg_a, dg_b, tol = locate_step(
                contact, t, g_a, g_b, dg_a, dg_b, tol, held_a, held_b, rem, bound, c, u, du, w, dw, s, work)
            held_a = held_b = False
            iterations += 1
            if not found and iterations == MAX_ITERATIONS:
                found, t_ev, which, search_bad = True, INF, 0, True
            if found:
                to = 0.0 if contact else (1.0 if which == 0 else -1.0)
                phase = AT_END
        if not bad and phase == AT_END:
            p, dp, q, dq, side, vl, vr, tl, instant, step_onsets, status = round_end(
                u, du, w, dw, rem, base, side, vl, vr, v, h, tl, instant, step_onsets, t_ev, to, search_bad, c, work)
            bad = status == FAILED
            phase = AT_STEP_END if status == DONE else AT_ROUND
        if bad and not end_period:  # failed in this pass: the period ends here, NaN
            p = dp = q = dq = top = bottom = NAN
            side = 0.0
            onsets += step_onsets
            end_period = True
        if not bad and phase == AT_STEP_END:
            onsets += step_onsets
            if observe:
                high, low = hermite_extremes(p0, dp0, p, dp, h)
                top, bottom = fmax(top, high), fmin(bottom, low)
            k += 1
            phase = AT_STEP
            end_period = k == samples
        if end_period:
            sections[period, i, 0], sections[period, i, 1] = p, dp
            sections[period, i, 2], sections[period, i, 3] = q, dq
            sides[period, i] = side
            impacts[period, i] = onsets
            tops[period, i], bottoms[period, i] = top, bottom
            period += 1
            k = onsets = 0
            top = bottom = p if observe and not bad else NAN
    state[0, i], state[1, i], state[2, i], state[3, i] = p, dp, q, dq
    state[4, i], state[5, i], state[6, i] = side, vl, vr
    failed[i] = bad
