"""Trajectories under a base input of their own: the march of a study whose base moves as the host
gives it (random excitation, a recorded ground motion), each trajectory with its own first-order
hold, the same step ``h`` for all.

A trajectory ``i`` of ``state`` ((7, n), as :mod:`.periods` has it) takes, over a block of ``B``
steps, the base through the nodes ``nodes[i, k]`` (m, ``B + 1`` of them: the first is where the last
block ended) with the slopes ``slopes[i, k]`` (m/s), exactly as an FMU fed ``base_displacement =
nodes[i, k]`` and ``base_velocity = slopes[i, k]`` at each step's start moves (each trajectory's
input a row: read in order). Each step goes as in
:mod:`.rounds`, and besides the motion the march writes ``p`` at each step's end (``positions``) and
the contact onsets in each step (``onsets``), and
adds to each trajectory's accumulators, step by step, what :mod:`.layout`'s ``S_*`` name of its
motion (``stats``), its contact onsets (``counts``) and its energy flows (``ledger``,
:mod:`.ledger`): kept across blocks, they come out the same bits however the input is cut.
"""

from .layout import (H_DECAY, H_EC, H_ES, H_STEP, L_C, L_CEQ, L_LEFT, L_PLASTIC, L_RIGHT, L_WORK, S_P2, S_PMAX,
                     S_U2, S_UMAX)
from .ledger import free_step_flows, segment_flows, switch_loss
from .location import next_event
from .periods import hermite_extremes, motion_of, store_motion
from .registry import source
from .rounds import FAILED, GOING, MAX_ROUNDS, contact_voltage, free_step, round_start, segment, switched
from .scalars import NAN, fmax


@source
def input_rounds(x, y0, v, h, c, work):
    """A hold step that may switch, event by event to its end, as :func:`.rounds.event_rounds` goes,
    with its energy flows: ``(x, onsets, failed, flows)``, ``flows`` the base's work, the dampers'
    dissipation, the plastic losses and the energy into the left and right loads (J)."""
    progress = (0.0, 0, 0)
    work_base = damper = barrier = plastic = left = right = 0.0
    for _ in range(MAX_ROUNDS):
        start = round_start(x, y0, v, progress[0], h)
        phase = (start[0], start[1], start[2], start[3], x[4])
        event = next_event(c, work, phase, contact_voltage(x[4], x[5], x[6], c), start[4])
        moved, dt, switch = segment(start, x, event, v, c, work)
        flows = segment_flows(start, x, moved, dt, v, c, work)
        work_base, damper, barrier = work_base + flows[0], damper + flows[1], barrier + flows[2]
        left, right = left + flows[3], right + flows[4]
        if switch:
            plastic += switch_loss(moved, c)
        x, progress, status = switched(moved, dt, switch, event, h, progress, c)
        if status != GOING:
            return x, progress[2], status == FAILED, (work_base, damper, barrier, plastic, left, right)
    return (NAN, NAN, NAN, NAN, 0.0, x[5], x[6]), progress[2], True, (work_base, damper, barrier, plastic, left,
                                                                       right)


@source(inline=True)
def input_step(x, y0, v, hold, c, work):
    """One hold step under the base ``y0 + v t`` (``hold``: the step's constants,
    :func:`.tables.input_hold`): ``(x, onsets, failed, flows)`` as :func:`input_rounds` returns them."""
    if x[4] == 0.0:
        x1, possible = free_step(x, y0, v, (hold[H_STEP], hold[H_EC], hold[H_ES], hold[H_DECAY]), c)
        if not possible:
            flows = free_step_flows(x, x1, y0, v, hold, c)
            return x1, 0, False, (flows[0], flows[1], flows[2], 0.0, flows[3], flows[4])
    return input_rounds(x, y0, v, hold[H_STEP], c, work)


@source
def march_input_one(i, state, failed, nodes, slopes, hold, c, positions, onsets, stats, counts, ledger, work):
    """Trajectory ``i`` through the block of ``slopes.shape[1]`` steps of its input, in place: its
    ``positions`` and ``onsets`` rows written (NaN and 0 from a failed location on), its ``stats``,
    ``counts`` and ``ledger`` rows added to (its ``stats`` NaN once it failed)."""
    x = motion_of(state, i)
    bad = failed[i]
    h = hold[H_STEP]
    squares, absolute, largest, largest_p = stats[i, S_U2], stats[i, S_P2], stats[i, S_UMAX], stats[i, S_PMAX]
    total = counts[i]
    flows = (ledger[i, L_WORK], ledger[i, L_C], ledger[i, L_CEQ], ledger[i, L_PLASTIC], ledger[i, L_LEFT],
             ledger[i, L_RIGHT])
    for k in range(slopes.shape[1]):
        if bad:
            positions[i, k] = NAN
            onsets[i, k] = 0
            continue
        y0, v, y1 = nodes[i, k], slopes[i, k], nodes[i, k + 1]
        p0, dp0 = x[0], x[1]
        x, count, bad, step = input_step(x, y0, v, hold, c, work)
        onsets[i, k] = count
        total += count
        flows = (flows[0] + step[0], flows[1] + step[1], flows[2] + step[2], flows[3] + step[3],
                 flows[4] + step[4], flows[5] + step[5])
        p1, dp1 = x[0], x[1]
        positions[i, k] = p1
        u1 = p1 - y1
        squares += u1 * u1
        absolute += p1 * p1
        high, low = hermite_extremes(p0 - y0, dp0 - v, u1, dp1 - v, h)
        largest = fmax(largest, fmax(high, -low))
        high, low = hermite_extremes(p0, dp0, p1, dp1, h)
        largest_p = fmax(largest_p, fmax(high, -low))
    if bad:
        squares = absolute = largest = largest_p = NAN
    stats[i, S_U2], stats[i, S_P2], stats[i, S_UMAX], stats[i, S_PMAX] = squares, absolute, largest, largest_p
    counts[i] = total
    ledger[i, L_WORK], ledger[i, L_C], ledger[i, L_CEQ] = flows[0], flows[1], flows[2]
    ledger[i, L_PLASTIC], ledger[i, L_LEFT], ledger[i, L_RIGHT] = flows[3], flows[4], flows[5]
    store_motion(state, i, x)
    failed[i] = bad

