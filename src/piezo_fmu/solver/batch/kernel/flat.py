"""The march of a GPU: :func:`.periods.march_one` as one flat loop of small pieces of work, the same
motion bit for bit in another order of work.

On a GPU the 32 threads of a warp execute one instruction together, and the nested loops of
``march_one`` (the hold steps of a period, the rounds of a step, the iterations of a search) have
different lengths for different trajectories: a warp would wait, at every hold step, for its
slowest thread's search. Here each trajectory's work is cut into the pieces those loops are made of,
and one loop runs them: each pass does, for every trajectory, at most one hold step's start, one
round's start, one step of its search and one round's end. A warp's threads stay together at the
top of the loop, whatever each has left to do.

The pieces are the source's own functions, called with the same numbers in the same order for each
trajectory: only the interleaving of trajectories differs, so both marches give the same bits.
"""

from .layout import NODES
from .location import MAX_ITERATIONS, locate_step, onset_side, phase_start, search_start
from .periods import hermite_extremes, hold_of, motion_of, store_motion, store_period
from .registry import source
from .rounds import DONE, FAILED, MAX_ROUNDS, contact_voltage, free_step, round_end, round_start
from .scalars import INF, NAN, fmax, fmin

#: What a trajectory does next: start a hold step, start a round, search, end a round, end a step.
AT_STEP, AT_ROUND, AT_SEARCH, AT_END, AT_STEP_END = range(5)


@source
def march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work):
    """:func:`.periods.march_one` (the same arguments, the same results) as one loop."""
    x = motion_of(state, i)
    bad = failed[i]
    g = groups[i]
    hold = hold_of(drive, g)
    h = hold[0]
    samples = (drive.shape[1] - NODES - 1) // 2
    periods = sections.shape[0]
    period = k = onsets = 0
    top = bottom = x[0] if observe and not bad else NAN
    stage = AT_STEP
    # the hold step's, the round's and the search's state
    y0 = v = p0 = dp0 = bound = to = 0.0
    progress = (0.0, 0, 0)
    rounds = iterations = 0
    start = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    phase = (0.0, 0.0, 0.0, 0.0, 0.0)
    search = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    event = (0.0, 0.0, False)
    held_a = held_b = False
    while period < periods:
        end_period = bad
        if not bad and stage == AT_STEP:
            y0, v = drive[g, NODES + k], drive[g, NODES + samples + 1 + k]
            p0, dp0 = x[0], x[1]
            stage = AT_ROUND
            if x[4] == 0.0:
                x1, possible = free_step(x, y0, v, hold, c)
                if not possible:
                    x = x1
                    stage = AT_STEP_END
            progress = (0.0, 0, 0)
            rounds = 0
        if not bad and stage == AT_ROUND:
            if rounds == MAX_ROUNDS:
                bad = True
            else:
                rounds += 1
                start = round_start(x, y0, v, progress[0], h)
                phase = (start[0], start[1], start[2], start[3], x[4])
                now, to, first, held_a, held_b, bound = phase_start(c, work, phase,
                                                                    contact_voltage(x[4], x[5], x[6], c))
                if now:
                    event = (0.0, to, False)
                    stage = AT_END
                else:
                    search = search_start(first, held_a, held_b)
                    iterations = 0
                    stage = AT_SEARCH
        if not bad and stage == AT_SEARCH:
            found, t_ev, which, search_bad, search = locate_step(search, held_a, held_b, start[4], bound, phase, c,
                                                                 work)
            held_a = held_b = False
            iterations += 1
            if not found and iterations == MAX_ITERATIONS:
                found, t_ev, which, search_bad = True, INF, 0, True
            if found:
                event = (t_ev, onset_side(phase, which, to), search_bad)
                stage = AT_END
        if not bad and stage == AT_END:
            x, progress, status = round_end(start, x, event, v, h, progress, c, work)
            bad = status == FAILED
            stage = AT_STEP_END if status == DONE else AT_ROUND
        if bad and not end_period:  # failed in this pass: the period ends here, NaN
            x = (NAN, NAN, NAN, NAN, 0.0, x[5], x[6])
            top = bottom = NAN
            onsets += progress[2]
            end_period = True
        if not bad and stage == AT_STEP_END:
            onsets += progress[2]
            if observe:
                high, low = hermite_extremes(p0, dp0, x[0], x[1], h)
                top, bottom = fmax(top, high), fmin(bottom, low)
            k += 1
            stage = AT_STEP
            end_period = k == samples
        if end_period:
            store_period(i, period, x, onsets, top, bottom, sections, sides, impacts, tops, bottoms)
            period += 1
            k = onsets = 0
            top = bottom = x[0] if observe and not bad else NAN
    store_motion(state, i, x)
    failed[i] = bad
