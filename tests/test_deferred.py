"""The root searches of free flight put off until a move may reach a root (``brackets.Searches``):
the same motion, events and ledger to the bit as locating every root when a bracket opens, and
never a root skipped.

Two independent routes: the core run both ways (``brackets.DEFER``) under moving bases, random
chops and snapshots; and the test that lets a search be skipped, held against the search itself on
polynomials made to have their roots just beyond the move's end, or grazing it."""

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st
from test_properties import base_inputs, chops, dampers

from piezo_fmu import Parameters, Simulator
from piezo_fmu.solver import brackets
from piezo_fmu.solver.batch import HarmonicHold
from piezo_fmu.solver.propagation import ORDER
from piezo_fmu.solver.roots import bernstein, crossings

DURATION = 0.2


def record(sim) -> str:
    """Everything a run leaves, as JSON text: each float written so that it reads back to the bit
    (shortest repr), NaN and -0.0 included, so equal texts are equal runs."""
    impacts = [dataclasses.asdict(i) for i in sim.impacts]
    return json.dumps([sim.snapshot(), impacts, sim.maxima, list(sim.reading_values())])


def marched(params, base, times, defer: bool, monkeypatch, snapshot_at: int | None = None) -> tuple:
    """The run of ``test_properties.run`` with the searches put off or not, its record after
    every move; from the move ``snapshot_at`` on, continued by a simulator restored from a snapshot."""
    amplitude, omega, _ = base
    monkeypatch.setattr(brackets, "DEFER", defer)
    sim, start, records = Simulator(params), 0.0, []
    for k, t in enumerate(times):
        if k == snapshot_at:
            sim = Simulator.restore(params, json.loads(json.dumps(sim.snapshot())))
        sim.advance(t, amplitude * math.sin(omega * start), amplitude * omega * math.cos(omega * start))
        start = t
        records.append((sim.state, sim.maxima[-1:], len(sim.impacts)))
    return records, record(sim), sim.brackets_opened


@st.composite
def circuits(draw):
    """A damper of ``test_properties.dampers`` under any voltage model (a load the model allows)."""
    params = draw(dampers())
    model = draw(st.sampled_from([0, 1, 2]))
    if not model:
        return params
    try:
        return dataclasses.replace(params, voltage_model=model, R_load=draw(st.floats(1e3, 1e7)))
    except ValueError:  # a load too small for the coupled contact's brackets (Parameters says so)
        reject()


@settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture], deadline=None,
          max_examples=150)
@given(params=circuits(), base=base_inputs(), sizes=st.lists(st.floats(1e-5, 0.02), min_size=1, max_size=80),
       snapshot=st.one_of(st.none(), st.integers(0, 80)))
def test_putting_the_searches_off_changes_no_bit_under_any_base_chop_or_snapshot(params, base, sizes, snapshot,
                                                                                 monkeypatch):
    times = chops(sizes, DURATION)
    put_off = marched(params, base, times, True, monkeypatch, snapshot)
    at_once = marched(params, base, times, False, monkeypatch, snapshot)
    assert put_off == at_once


def test_the_harness_hold_at_resonance_is_the_same_to_the_bit_and_skips_most_searches(monkeypatch):
    # 1.25 w_n with its two impacts a period and 0.95 w_n with six: a new bracket every step.
    searched = []  # the put-off searches that ran (a contact bracket's run at once)
    run = brackets.Searches.run
    monkeypatch.setattr(brackets.Searches, "run", lambda self, br: (br.deferred is self and searched.append(1),
                                                                    run(self, br))[1])
    for ratio in (1.25, 0.95):
        hold = HarmonicHold(ratio * math.sqrt(1000.0), 1e-3)
        nodes, slopes = (a.tolist() for a in hold.nodes())
        n = hold.samples
        runs = {}
        for defer in (True, False):
            monkeypatch.setattr(brackets, "DEFER", defer)
            searched.clear()
            sim = Simulator(Parameters(voltage_model=1, R_load=3.59e6, p0=1e-3, q0=1e-3), y0=nodes[0])
            for k in range(20 * n):
                sim.advance((k + 1) * hold.step, nodes[k % n], slopes[k % n])
            runs[defer] = record(sim)
            if defer:
                counted = (len(searched), sim.brackets_opened, len(sim.impacts))
        assert runs[True] == runs[False]
        # impacts more than one a period; the searches run in a fifth of the brackets at most:
        # those where a step may meet a root
        assert counted[2] > 20, counted
        assert counted[0] <= counted[1] / 5, counted


def polynomial(draw) -> np.ndarray:
    """A bracket's polynomial in its normalised time: a damped turn of at most 2 rad (the
    coefficients of ``c cos + d sin`` of ``theta s``, scaled) plus a constant, often near zero; or
    a turn that grazes zero at ``s0``, crossing it twice close together."""
    theta = draw(st.floats(0.05, 2.0))
    k = np.arange(ORDER + 1)
    factorial = np.array([math.factorial(j) for j in k], dtype=float)
    if draw(st.booleans()):
        # cos(theta (s - s0)) - (1 - eps): two roots at s0 +- sqrt(2 eps) / theta
        s0, eps = draw(st.floats(0.05, 0.95)), draw(st.sampled_from([1e-2, 1e-4, 1e-8, 1e-12]))
        growth = np.array([(1j * theta) ** j for j in k]) / factorial * np.exp(-1j * theta * s0)
        a = growth.real
        a[0] -= 1.0 - eps
    else:
        c, d = draw(st.floats(-1.0, 1.0)), draw(st.floats(-1.0, 1.0))
        growth = np.array([(complex(-draw(st.floats(0.0, 1.0)), 1.0) * theta) ** j for j in k]) / factorial
        a = c * growth.real + d * growth.imag
        a[0] += draw(st.one_of(st.floats(-1.0, 1.0), st.floats(-1e-9, 1e-9), st.just(0.0)))
    return a * draw(st.sampled_from([1e-3, 1.0, 1e3]))


@settings(deadline=None, max_examples=1000)
@given(data=st.data())
def test_a_search_shown_clear_up_to_a_moves_end_reports_no_root_before_it(data):
    a = polynomial(data.draw)
    noise = data.draw(st.sampled_from([0.0, 1e-16, 1e-12])) * float(np.abs(a).sum())
    # the core computes a bracket's Bernstein coefficients apart from its power coefficients, each
    # to its own rounding: within about the rounding level noise of each other
    b = bernstein(a) + noise * np.array(data.draw(st.lists(st.floats(-1.0, 1.0), min_size=ORDER + 1,
                                                               max_size=ORDER + 1)))
    found = {direction: crossings(a, direction, b, noise) for direction in (+1, -1)}
    # the move's end: anywhere, just before the first root the searches report, or just after a
    # root (past a grazing pair, the polynomial has the sign it started with again)
    roots = sorted(found[+1] + found[-1])
    ends = [data.draw(st.floats(1e-4, 0.999))] + [r * (1 - data.draw(st.sampled_from([1e-2, 1e-6, 1e-9])))
                                                  for r in roots[:1]] + [min(r * 1.001, 0.999) for r in roots]
    for end in ends:
        if brackets._clear(a.tolist(), noise, end + brackets.DEFER_MARGIN):
            assert all(r > end for r in found[+1] + found[-1]), (found, end)


def test_a_search_shown_clear_is_the_common_case_and_a_root_near_the_end_is_never_shown_clear():
    # p' of an oscillation that falls through zero at s = 0.5 (a quarter turn of 2 rad later)
    growth = np.array([(2j) ** j / math.factorial(j) for j in range(ORDER + 1)])
    a = (growth * np.exp(1j * (math.pi / 2 - 1.0))).real  # cos(pi/2 - 1 + 2 s): zero at s = 0.5
    root = crossings(a, -1)
    assert root == [pytest.approx(0.5, abs=1e-15)]
    assert brackets._clear(a.tolist(), 0.0, 0.04)  # a step of a 64-step period on a 2 rad bracket
    assert brackets._clear(a.tolist(), 0.0, 0.3)
    for end in (0.49, 0.5, 0.6):
        assert not brackets._clear(a.tolist(), 0.0, end)
