"""The co-simulation FMU keeps any host's clock (``piezo_fmu.fmi.clock``), however long the run.

1. The clock's own functions, compiled with numba, are run against the time arithmetic of each
   kind of host for 10^8 steps at twelve step sizes (round and irrational), without the FMU: no
   start is refused, and the host's start is never farther from the FMU's time than the FMU's snap
   to the nanosecond plus a few ulp. The same march, given a clock that accepted a start only
   within the snap's own window (what the FMU did before), finds that clock's refusals at the very
   steps where both FMUs refused a plain fixed-step loop: so the march can fail.
2. What is refused: a start that repeats or skips a step, in runs of up to 3e11 steps.
3. Both FMUs marched 2e5 steps of ``doStep(i * h, h)`` at three step sizes, in fmpy and in the C
   host (``hosts/native_host.c --clock multiply``): every step is taken, and the two hosts and
   the two FMI versions end on the same bits.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from piezo_fmu import Parameters
from piezo_fmu.fmi import clock
from test_fmi3 import Host, fmus  # noqa: F401 - fmus is the fixture Host takes

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from hosts import native  # noqa: E402

W_N = math.sqrt(Parameters().K / Parameters().M)
#: 64 steps a forcing period at 1.5, 1.2 and 0.8 w_n, and the step ``i`` at which both FMUs refused
#: ``doStep(i * h, h)`` at each while they accepted a start only within their snap's window.
ISSUE_STEPS = tuple(2.0 * math.pi / (ratio * W_N) / 64 for ratio in (1.5, 1.2, 0.8))
REFUSED = (111_546, 111_815, 101_518)
#: The step sizes of the clock's march (s): the three above, round ones, and irrational ones.
STEPS = (*ISSUE_STEPS, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 0.1, 1.0 / 3.0, math.pi * 1e-3, math.e * 1e-5)
#: Where each of them starts (s): from 0, and two from an awkward start.
STARTS = (0.0,) * 6 + (1.0 / 3.0,) + (0.0,) * 4 + (1e3,)
MARCH = 10**8
#: How far a host's start may lie from the FMU's time, in units of the snap's window
#: ``SNAP * max(1 s, |t|)``: the snap plus 4 ulp of ``t`` (2.2e-16 |t| each, 2.2e-4 of the window).
SNAP_AND_ROUNDING = 1.001

#: Each host's arithmetic: its time ``t_k``, and the step it passes from there.
HOSTS = {
    "t0 + i*h": "the plain fixed-step loop: doStep(t0 + i*h, h)",
    "t += h": "repeated addition (ecos): doStep(t, h), then t += h",
    "fmusim, fmpy": ("t_k = start + k*h, the step t_{k+1} - t_k (Reference-FMUs' fmusim; fmpy 0.3.32's "
                     "simulate_fmu computes the same: test_fmpy_steps_as_fmusim_does)"),
    "integer ns": ("integer nanoseconds: t_k = (n0 + k*n_h) / 1e9, the step t_{k+1} - t_k (OSP libcosim's "
                   "std::chrono conversion, the project's C host)"),
}


def compile_march(host: str, continues, step_end):
    """A numba march of ``continues`` and ``step_end`` (the clock's functions, or others) under the
    arithmetic of ``host``, over lanes of step sizes: ``march(starts, steps, n)`` returns, for each
    lane, the first step whose start is refused (-1: none), how many are refused, how many start
    farther from the FMU's time than :data:`SNAP_AND_ROUNDING` allows, and how far the FMU's time
    lies from the host's after the last step, in units of the snap's window."""
    kind = tuple(HOSTS).index(host)
    continues, step_end = numba.njit(continues), numba.njit(step_end)
    window = clock.SNAP * SNAP_AND_ROUNDING

    @numba.njit
    def march(starts, steps, n):
        lanes = steps.size
        ns0, ns_h = np.empty(lanes, np.int64), np.empty(lanes, np.int64)
        host, fmu = np.empty(lanes), np.empty(lanes)
        for lane in range(lanes):
            ns0[lane], ns_h[lane] = round(starts[lane] * 1e9), round(steps[lane] * 1e9)
            host[lane] = ns0[lane] / 1e9 if kind == 3 else starts[lane]
            fmu[lane] = host[lane]  # the FMU starts at the host's start time
        first, refused, beyond = np.full(lanes, -1, np.int64), np.zeros(lanes, np.int64), np.zeros(lanes, np.int64)
        for i in range(n):
            for lane in range(lanes):
                t, h, t0 = host[lane], steps[lane], starts[lane]
                if kind == 0:
                    t_next, size = t0 + (i + 1) * h, h
                elif kind == 1:
                    t_next, size = t + h, h
                elif kind == 2:
                    t_next = t0 + (i + 1) * h
                    size = t_next - t
                else:
                    t_next = (ns0[lane] + (i + 1) * ns_h[lane]) / 1e9
                    size = t_next - t
                now = fmu[lane]
                if not continues(now, t):
                    refused[lane] += 1
                    if first[lane] < 0:
                        first[lane] = i
                if abs(t - now) > window * max(1.0, abs(now)):
                    beyond[lane] += 1
                fmu[lane] = step_end(now, t, size)
                host[lane] = t_next
        gap = np.abs(host - fmu) / (clock.SNAP * np.maximum(1.0, np.abs(fmu)))
        return first, refused, beyond, gap

    return march


@pytest.mark.parametrize("host", HOSTS)
def test_no_host_arithmetic_is_refused_in_1e8_steps(host):
    march = compile_march(host, clock.continues, clock.step_end)
    first, refused, beyond, gap = march(np.array(STARTS), np.array(STEPS), MARCH)
    for h, t0, k, count, far, last in zip(STEPS, STARTS, first, refused, beyond, gap):
        case = f"{HOSTS[host]}, h = {h!r} s from {t0!r} s"
        assert count == 0, f"{case}: {count} starts refused, the first at step {k}"
        assert far == 0, f"{case}: {far} starts farther from the FMU's time than its snap and rounding"
        assert last <= SNAP_AND_ROUNDING, f"{case}: the FMU ends {last:.4g} snap windows from the host"


def test_a_clock_that_accepts_only_its_snap_window_fails_the_march_where_the_fmus_did():
    """Before the fix, the FMU accepted a start only within the snap's window, so that a snap and one
    rounding of ``i * h`` crossed it: the march finds exactly the steps at which both FMUs refused
    a plain fixed-step loop, and passes every other host (they round nothing the FMU does not)."""
    def snap_window_only(t_now, current_time):
        return abs(current_time - t_now) <= clock.SNAP * max(1.0, abs(t_now))

    march = compile_march("t0 + i*h", snap_window_only, clock.step_end)
    first, refused, _, _ = march(np.zeros(3), np.array(ISSUE_STEPS), 120_000)
    assert tuple(first) == REFUSED
    assert (refused > 0).all()
    march = compile_march("t += h", snap_window_only, clock.step_end)
    assert (march(np.zeros(3), np.array(ISSUE_STEPS), 120_000)[1] == 0).all()


def test_fmpy_steps_as_fmusim_does():
    """fmpy 0.3.32's co-simulation loop (``simulateCS``) computes its communication points as
    fmusim does: the march's ``fmusim, fmpy`` host is both."""
    import fmpy.simulation

    source = Path(fmpy.simulation.__file__).read_text()
    loop = source[source.index("def simulateCS("):]
    assert "next_regular_point = start_time + (n_steps + 1) * output_interval" in loop
    assert "step_size = next_communication_point - time" in loop
    assert "fmu.doStep(currentCommunicationPoint=time, communicationStepSize=step_size)" in loop


# -- what is refused ----------------------------------------------------------------------------------

@pytest.mark.parametrize("h", STEPS)
@pytest.mark.parametrize("n", [1, 10**3, 10**8, 3 * 10**11])
def test_a_start_that_repeats_or_skips_a_step_is_refused_in_a_run_of_up_to_3e11_steps(h, n):
    t = n * h
    for moved in (0.0, clock.SNAP, -clock.SNAP):  # the FMU's time, after its end was moved onto a nanosecond
        now = t + moved * max(1.0, t)
        assert clock.continues(now, t)
        assert not clock.continues(now, t - h), "a repeated step"
        assert not clock.continues(now, t + h), "a skipped step"
    assert not clock.continues(t, math.nan)


@pytest.mark.parametrize("t", [0.0, 0.5, -3.0, 230.86741306176913, 86400.0, 3.2e7])
def test_a_start_is_taken_within_twice_the_snap_window_and_not_beyond(t):
    tolerance = clock.ACCEPT * max(1.0, abs(t))
    for side in (1.0, -1.0):
        inside = t + side * tolerance
        if abs(inside - t) > tolerance:  # t +- tolerance rounded outwards
            inside = math.nextafter(inside, t)
        assert clock.continues(t, inside)
        assert not clock.continues(t, math.nextafter(inside, side * math.inf))


def test_a_step_end_is_snapped_to_a_nanosecond_within_its_window_and_never_before_the_fmu():
    assert clock.step_end(0.0, 0.5, 0.5 + 0.9e-12) == 1.0
    assert clock.step_end(0.0, 0.5, 0.5 + 1.1e-12) == 0.5 + (0.5 + 1.1e-12)
    assert clock.step_end(300.0, 300.0, 0.25e-9) == 300.0 + 0.25e-9  # the nanosecond would be the FMU's time
    assert clock.step_end(0.01, 0.01, 1e-300) == 0.01  # below the resolution of a double
    # A step shorter than the clock's tolerance, started before the FMU's time, leaves it there.
    t = 300.0 + 0.2e-9
    assert clock.continues(t, 300.0) and clock.step_end(t, 300.0, 0.1e-9) == t


@pytest.mark.parametrize("version", [2, 3])
def test_a_step_within_the_tolerance_that_ends_before_the_fmu_changes_nothing(fmus, version):  # noqa: F811
    host = Host(fmus, version)  # a refused step raises; the FMI 3.0 host also collects the errors logged
    h = 1e-3
    for k in range(300):
        host.step(k * h, h)
    before = host.outputs()
    host.step(0.3 - 0.4e-12, 0.2e-12)  # within 2e-12 s of 0.3 s, ending before it
    assert host.outputs() == before and host.errors() == []
    host.step(0.3 - 0.2e-12, h)
    assert host.errors() == []
    host.close()


# -- both FMUs, 2e5 steps of doStep(i * h, h) ------------------------------------------------------------

FMU_STEPS = 200_000


def read_time(host: Host) -> float:
    return host.fmu.getFloat64([host.variables["time"].valueReference])[0]


@pytest.fixture(scope="module")
def fmpy_marches(fmus):  # noqa: F811
    """Both FMUs (by FMI version, h) after 2e5 steps of ``doStep(i * h, h)`` in fmpy, or up to the
    first step refused: the steps taken, the outputs, and the FMI 3.0 FMU's time."""
    finals = {}
    for version in (2, 3):
        for h in ISSUE_STEPS:
            host = Host(fmus, version)
            step, taken = host.fmu.doStep, 0
            try:
                for taken in range(FMU_STEPS):
                    step(taken * h, h)
                taken = FMU_STEPS
            except FMICallException:
                pass
            finals[version, h] = taken, host.outputs(), read_time(host) if version == 3 else None
            host.close()
    return finals


@pytest.mark.parametrize("h", ISSUE_STEPS)
def test_both_fmus_take_2e5_steps_of_a_plain_fixed_step_loop_in_fmpy(fmpy_marches, h):
    (taken2, outputs2, _), (taken3, outputs3, t) = fmpy_marches[2, h], fmpy_marches[3, h]
    assert taken2 == taken3 == FMU_STEPS, "the step refused"
    assert outputs3 == outputs2
    assert abs(t - FMU_STEPS * h) <= clock.SNAP * SNAP_AND_ROUNDING * FMU_STEPS * h
    assert outputs2["impact_count"] > 0


@pytest.fixture(scope="module")
def c_host(tmp_path_factory) -> Path:
    return native.build(tmp_path_factory.mktemp("native") / "native_host")


@pytest.mark.parametrize("h", ISSUE_STEPS)
def test_both_fmus_take_2e5_steps_of_a_plain_fixed_step_loop_in_the_c_host(fmpy_marches, c_host, h, tmp_path):
    for version, fmu in ((2, "PiezoImpactDamper.fmu"), (3, "PiezoImpactDamper3.fmu")):
        out = tmp_path / f"fmi{version}.csv"
        native.run(ROOT / "fmus" / fmu, out, ["--clock", "multiply", "--step", repr(h), "--stop", repr(FMU_STEPS * h),
                                                "--every", str(FMU_STEPS)], executable=c_host)
        names, *rows = [line.split(",") for line in out.read_text().splitlines()]
        assert [float(row[0]) for row in rows] == [0.0, FMU_STEPS * h]  # a row at the start and after the last step
        last = {name.strip('"'): float(value) for name, value in zip(names[1:], rows[-1][1:])}
        assert last == fmpy_marches[version, h][1]  # the same bits as fmpy's
