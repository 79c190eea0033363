"""``piezo-fmu random``: the damper under random base excitation, shown right by routes independent of
the batch engine that marches it:

- the linear limit: with a gap no motion reaches, the relative displacement's variance is the
  integral of the input's PSD times the base-excited oscillator's ``|H|^2`` (the excitation's
  oracle, a quadrature), within the Monte Carlo interval, for white noise and for Kanai-Tajimi;
  and the response PSD follows ``|H|^2 G``;
- a saved realization, replayed through the FMU with fmpy alone (``simulate_fmu(..., input=...)``),
  gives the study's motion to 1e-9 m over its first seconds, and its RMS and impacts over the window
  within the realizations' scatter;
- the energy ledger closes for every realization;
- a record (``--record``) is marched as recorded: with a gap no motion reaches, the main mass follows
  the base-excited oscillator stepped by scipy's matrix exponential over the record's own input
  rows, and a single realization's intervals are absent, not numbers;
- one realization's bits do not depend on how many realizations run, on the workers, or on the
  block length;
- bad input is refused with the value and what is allowed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from fmu_host import assert_refused, run_cli

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
COMMON = ("--jobs", 1, "--no-progress", "--fmu", FMU)


def run(tmp_path: Path, name: str, *argv) -> tuple[Path, dict]:
    out = tmp_path / name
    assert run_cli("random", *argv, *COMMON, "--out", out) == 0
    return out, json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def wide(tmp_path_factory):
    """Kanai-Tajimi firm soil and band-limited white noise, 300 realizations of a 60 s window, with a
    gap no motion reaches (1 m; the RMS is some 3 mm): linear both with and without."""
    folder = tmp_path_factory.mktemp("wide")
    return {psd: run(folder, psd, "--psd", psd, "--band", *band, "--set", "d=1", "--realizations", 300,
                     "--duration", 60, "--confirm", 0)
            for psd, band in (("kanai-tajimi", (0, 25)), ("white", (1, 20)))}


@pytest.mark.parametrize("psd", ["kanai-tajimi", "white"])
def test_without_impacts_the_variance_is_the_psd_times_the_oscillators_gain_squared(wide, psd):
    """The RMS of the relative displacement, with and without the damper (both linear here), against
    the oracle's ``sqrt(int |H|^2 G |HP|^2 df)``: within four standard errors of the realizations'
    mean square (the study's own 95% interval is two); no impact, and the pair's ratio 1."""
    _, summary = wide[psd]
    (level,) = summary["levels"]
    linear = level["without"]["rms_relative_linear"]
    for case in ("with", "without"):
        rms, low, high = level[case]["rms_relative"], *level[case]["rms_relative_ci"]
        half = (high ** 2 - low ** 2) / 4.0  # the mean square's standard error times 1.96
        assert abs(rms ** 2 - linear ** 2) <= 4.0 / 1.96 * half, (case, rms, linear)
        assert level[case]["impacts_per_second"] == 0.0
    assert level["ratio"] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("psd", ["kanai-tajimi", "white"])
def test_without_impacts_the_response_psd_follows_the_oscillators_gain_squared_times_the_input(wide, psd):
    """The Welch PSD of the relative displacement against ``|H|^2 G |HP|^2`` bin by bin over the band,
    away from the resonance (where 20 s segments cannot resolve a peak 0.016 Hz wide): within 5
    standard deviations of an average of its segments, and on average within 2%."""
    folder, summary = wide[psd]
    table = np.genfromtxt(folder / "psd.csv", delimiter=",", names=True)
    f = table["frequency_Hz"]
    natural = math.sqrt(summary["values"]["K"] / summary["values"]["M"]) / (2 * math.pi)
    top = summary["excitation"]["source"]["upper_Hz"]
    low = max(summary["excitation"]["highpass"]["corner_Hz"] * 5, summary["excitation"]["source"]["lower_Hz"] * 1.2)
    band = (f > low) & (f < 0.8 * top) & (np.abs(f - natural) > 1.0)
    ratio = table["psd_without_level0_m2_per_Hz"][band] / table["psd_linear_level0_m2_per_Hz"][band]
    segments = 300 * (60.0 / 10.0 - 1)  # realizations x segments of 20 s, half overlapping, in 60 s
    sigma = 1.0 / math.sqrt(segments)
    assert band.sum() > 100
    assert np.abs(ratio - 1.0).max() < 5 * sigma * 2  # Hann's overlap: about twice the independent segments' sigma
    assert abs(ratio.mean() - 1.0) < 0.02


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """The nominal damper at the default level: 24 realizations of 20 s after the warm-up, realization
    5 saved, the FMU checking two."""
    folder = tmp_path_factory.mktemp("saved")
    return run(folder, "saved", "--realizations", 24, "--duration", 20, "--save-input", 5, "--confirm", 2)


def test_a_saved_realization_replayed_by_fmpy_alone_gives_the_studys_motion(saved):
    """``input_5.csv`` through the FMU with ``fmpy.simulate_fmu`` alone, the values of
    ``summary.json``: the main mass within 1e-9 m of ``response_5.csv`` over the first 2 s (some 20
    impacts; the motion is chaotic, and rounding's differences grow past 1e-12 m after about 30
    impacts, 3.4 s here), and over the window the RMS within the check's tolerance (once chaos has
    parted two codes' trajectories, they are two motions under one input)."""
    from fmpy import simulate_fmu

    from piezo_fmu_harness.excitation import read_replay_csv

    folder, summary = saved
    rows = read_replay_csv(folder / "input_5.csv")
    response = np.genfromtxt(folder / "response_5.csv", delimiter=",", names=True)
    step, stop = summary["saved"]["step_s"], summary["saved"]["stop_time_s"]
    result = simulate_fmu(str(FMU), start_values=summary["values"], input=rows, step_size=step,
                          output_interval=step, stop_time=stop, output=["main_displacement", "impact_count"])
    assert len(result) == len(response)
    assert np.array_equal(result["time"], response["time"]) or np.abs(result["time"] - response["time"]).max() < 1e-9
    first = result["time"] <= 2.0
    assert response["impact_count"][first][-1] > 10  # the damper works in the compared stretch
    assert np.abs(result["main_displacement"][first] - response["main_displacement"][first]).max() < 1e-9
    window = result["time"] > summary["warmup_s"]
    relative = lambda p: np.sqrt(np.mean((p[window] - np.interp(result["time"][window], rows["time"],  # noqa: E731
                                                                   rows["base_displacement"])) ** 2))
    check = {c["realization"]: c for c in summary["fmu_checks"]["checks"]}[5]
    assert check["agrees"]
    assert abs(relative(result["main_displacement"]) - relative(response["main_displacement"])) \
        <= check["tolerance_rms_relative_m"]


def test_the_fmu_checks_follow_the_engine_over_the_first_second(saved):
    _, summary = saved
    checks = summary["fmu_checks"]
    assert checks["checked"] == checks["agree"] == 2 and checks["checks"][0]["realization"] == 5
    for check in checks["checks"]:
        assert check["largest_gap_first_second_m"] <= 1e-9 and check["agrees"]


def test_the_energy_ledger_closes_for_every_realization(saved):
    """The base's work equals the stored energy's change, the dissipated, plastic and harvested
    energy over the window, for every realization with and without the damper: within 1e-11 of the
    work (the kernel's rounding over 5,000 steps and hundreds of impacts)."""
    folder, summary = saved
    with xr.open_dataset(folder / "random.nc", engine="h5netcdf") as ds:
        balance = ds["balance"].values
        power = ds["power"].sel(damper="with").values
    assert np.isfinite(balance).all() and (power > 0).all()
    (level,) = summary["levels"]
    assert level["ledger_relative_max"] < 1e-11


def test_one_realizations_bits_do_not_depend_on_the_others_the_workers_or_the_block(tmp_path, monkeypatch):
    """Realization 3's record: in a chunk of 6 and alone; with blocks of 4096 steps and of 777; and a
    whole study on one worker and on two: the same bits."""
    from piezo_fmu_harness.random_response import march
    from piezo_fmu_harness.random_response.spec import RandomSpec

    out, summary = run(tmp_path, "one", "--realizations", 6, "--duration", 10, "--warmup", 2, "--confirm", 0)
    header = json.loads((out / "random.json").read_text())
    spec = {k: v for k, v in header.items() if k != "fmu_guid"}
    RandomSpec.from_dict(spec)
    together = march.march_chunk(None, spec, 0, list(range(6)))["realizations"][3]
    alone = march.march_chunk(None, spec, 0, [3])["realizations"][0]
    monkeypatch.setattr(march, "BLOCK", 777)
    blocked = march.march_chunk(None, spec, 0, [3])["realizations"][0]
    assert together == alone == blocked
    assert together["levels"][0]["with"]["impacts"] > 0
    monkeypatch.undo()
    two = tmp_path / "two"
    assert run_cli("random", "--realizations", 6, "--duration", 10, "--warmup", 2, "--confirm", 0, "--jobs", 2,
                   "--no-progress", "--fmu", FMU, "--out", two) == 0
    for name in ("random.csv", "psd.csv"):
        assert (out / name).read_bytes() == (two / name).read_bytes(), name


@pytest.mark.parametrize("argv, words", [
    (("--level", -0.01), ["--level", "-0.01", "allowed range (0, inf) (m/s^2)^2/Hz"]),
    (("--psd", "white", "--band", 5, 2), ["fmin", "allowed"]),
    (("--step", 0.05), ["upper = 25 Hz", "allowed: upper <= fs/4 = 5 Hz"]),
    (("--voltage-model", 1), ["--voltage-model 1", "allowed: 0", "or 2"]),
    (("--set", "C=0"), ["C = 0.0 N.s/m", "allowed range (0, inf) N.s/m"]),
    (("--set", "C=5e-90"), ["C = 5e-90 N.s/m", "steps of 0.004 s a realization", "allowed: at most 1e+09",
                            "--set C of at least 1.73e-06 N.s/m"]),
    (("--warmup", 1e300), ["1e+300 s of warm-up", "allowed: at most 1e+09"]),
    (("--set", "K=1e23"), ["the FMU rejects K = 1e+23", "allowed range: at least 1e-09 s"]),
    (("--set", "t_p=5e-324", "--set", "rho_p=5e-324", "--set", "g31=1e308", "--set", "barrier_mode=1"),
     ["--load: the default load R_load = 1/(omega_c C_p) = 0 Ohm", "allowed range (0, inf) Ohm", "C_p = inf F"]),
    (("--realizations", 3, "--save-input", 3), ["--save-input 3", "allowed range [0, 2]"]),
    (("--envelope", "jennings:1,2"), ["--envelope jennings:1,2", "3 numbers"]),
    (("--band", 1, 20), ["--band 1 20", "allowed: --band 0 FMAX"]),
])
def test_bad_input_is_refused_with_the_value_and_what_is_allowed(capsys, tmp_path, argv, words):
    assert_refused(capsys, "random", [*argv, *COMMON, "--out", tmp_path / "out"], words)


def test_a_malformed_psd_table_is_refused_with_its_file_and_line(capsys, tmp_path):
    table = tmp_path / "psd.csv"
    table.write_text("frequency,psd\n1,0.01\n2,oops\n")
    assert_refused(capsys, "random", ["--psd", table, *COMMON, "--out", tmp_path / "out"], [str(table), "line 3"])


def test_a_record_is_marched_as_the_linear_oscillator_under_its_rows_with_no_interval_claimed(tmp_path):
    """A 20 s record (filtered noise, 4 ms step) with a 1 m gap: no impact, so the main mass obeys
    ``M x'' + C (x' - v_k) + K (x - y_k - v_k (t - t_k)) = 0`` on each step of the replayed rows
    (the FMU's first-order hold). Stepped by ``scipy.linalg.expm`` of that system, a route that
    shares nothing with the core's series, it gives ``response_0.csv`` within 1e-12 m (the
    rounding of 5,000 steps of a 6 cm motion). One realization: the ratio is 1, the base's RMS the
    record's, every interval null in summary.json, and the FMU's check agrees."""
    from scipy.linalg import expm

    rng = np.random.default_rng(7)
    step, count = 0.004, 5000
    acceleration = 0.6 * np.convolve(rng.standard_normal(count), np.ones(8) / 8, mode="same")
    record = tmp_path / "record.csv"
    np.savetxt(record, np.column_stack([np.arange(count) * step, acceleration]), delimiter=",",
               header="time,acceleration", comments="", fmt="%.17g")
    folder, summary = run(tmp_path, "record", "--record", record, "--set", "d=1", "--confirm", 1,
                          "--save-input", 0)
    rows = np.genfromtxt(folder / "input_0.csv", delimiter=",", names=True)
    response = np.genfromtxt(folder / "response_0.csv", delimiter=",", names=True)
    values = summary["values"]
    M, K, C = values["M"], values["K"], values["C"]
    system = np.array([[0, 1, 0, 0], [-K / M, -C / M, K / M, C / M], [0, 0, 0, 1], [0, 0, 0, 0.0]])
    advance = expm(system * summary["saved"]["step_s"])
    state, path = np.zeros(2), [0.0]
    for y, v in zip(rows["base_displacement"], rows["base_velocity"]):
        state = (advance @ np.array([state[0], state[1], y, v]))[:2]
        path.append(state[0])
    assert len(path) == len(response) == count + 1 and response["impact_count"][-1] == 0
    assert np.abs(response["main_displacement"]).max() > 0.01  # the base moved the mass
    assert np.abs(np.array(path) - response["main_displacement"]).max() < 1e-12
    (level,) = summary["levels"]
    assert level["realizations"] == 1 and level["ratio"] == pytest.approx(1.0, abs=1e-12)
    assert level["base_acceleration_rms"] == pytest.approx(np.sqrt(np.mean(acceleration ** 2)), rel=1e-12)
    assert level["ratio_ci"] == [None, None] and level["with"]["peak_p95_ci"] == [None, None]
    assert summary["fmu_checks"]["checks"][0]["agrees"]


@pytest.mark.parametrize("q, count", [(0.5, 40), (0.95, 200)])
def test_a_quantiles_interval_covers_it_at_least_95_percent_of_the_time(q, count):
    """The order statistics :func:`quantile_interval` picks, over 4,000 samples of ``count``
    uniform values, bracket the true quantile ``q`` at least 94% of the time (95% less three of
    the estimate's standard errors, 0.34% each); and too few values give no interval at all."""
    from piezo_fmu_harness.random_response.statistics import quantile_interval

    rng = np.random.default_rng(11)
    hits = sum(low <= q <= high for _, low, high in (quantile_interval(rng.random(count), q) for _ in range(4000)))
    assert hits / 4000 >= 0.94
    _, low, high = quantile_interval(rng.random(58), 0.95)  # 1 - 0.95^58 = 0.949: below 95% even with the extremes
    assert math.isnan(low) and math.isnan(high)
    assert not math.isnan(quantile_interval(rng.random(59), 0.95)[1])


@pytest.mark.parametrize("count", [2, 5, 1000])
def test_the_window_check_flags_two_honest_realizations_no_more_often_than_its_level(count):
    """Two codes that march the same input and have parted differ over the window as two
    realizations do. With the scatter estimated from ``count`` normal realizations, the check's
    tolerance flags such a pair in 0.27% of cases (three normal deviations) whatever ``count``:
    within 0.27% +- 0.15% over 40,000 trials (four of the estimate's standard errors); with 3 fixed
    deviations in place of Student's ``t``, two realizations would be flagged in 20% of cases."""
    from piezo_fmu_harness.studies.random.trace import verdict

    rng = np.random.default_rng(5)
    trials, flagged = 40_000, 0
    for _ in range(trials):
        sample = rng.standard_normal(count)
        fmu, engine = rng.standard_normal(2)
        spread = {"rms_relative": float(np.std(sample, ddof=1)), "impacts": 1e300, "count": count}
        check = {"largest_gap_first_second_m": 0.0, "rms_relative_fmu": fmu, "rms_relative_engine": engine,
                 "impacts_fmu": 0, "impacts_engine": 0}
        flagged += not verdict(check, spread)["agrees"]
    assert abs(flagged / trials - 0.0027) < 0.0015


@pytest.mark.parametrize("rate", [0.5, 7.0])
@pytest.mark.parametrize("count", [2, 5, 1000])
def test_the_window_check_flags_honest_impact_counts_no_more_often_than_its_level(rate, count):
    """Impact counts are whole numbers, and a few short realizations often have the same count (all
    7), an estimated scatter of 0. With the count's rounding variance (1/12) added, the check flags two
    honest Poisson counts of mean ``rate`` (an FMU and an engine that parted) in at most 0.27% of
    cases plus 0.18% (four standard errors of 20,000 trials, and the counts' discreteness); without
    it, two realizations of mean 0.5 would be flagged in 24% of cases, of mean 7 in 9%."""
    from piezo_fmu_harness.studies.random.trace import verdict

    rng = np.random.default_rng(1)
    trials, flagged = 20_000, 0
    for _ in range(trials):
        sample = rng.poisson(rate, count)
        fmu, engine = rng.poisson(rate, 2)
        spread = {"rms_relative": 1e300, "impacts": float(np.std(sample, ddof=1)), "count": count}
        check = {"largest_gap_first_second_m": 0.0, "rms_relative_fmu": 0.0, "rms_relative_engine": 0.0,
                 "impacts_fmu": int(fmu), "impacts_engine": int(engine)}
        flagged += not verdict(check, spread)["agrees"]
    assert flagged / trials < 0.0027 + 0.0018


@pytest.mark.parametrize("pairs", [5, 50])
def test_the_paired_ratios_interval_covers_the_true_ratio_95_percent_of_the_time(pairs):
    """Paired mean squares with a known ratio of means (``b`` gamma-distributed, ``a = 0.08 b g``
    with ``g`` of mean 1, so the RMS ratio is ``sqrt(0.08)``): over 4,000 studies of ``pairs``
    realizations the interval covers it at least 94% of the time (95% less three standard errors).
    With the normal quantile in place of Student's, five pairs would be covered some 87% of the
    time."""
    from piezo_fmu_harness.random_response.statistics import paired_ratio

    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(4000):
        without = rng.gamma(20.0, 1.0, pairs)
        _, low, high = paired_ratio(0.08 * without * rng.gamma(30.0, 1 / 30, pairs), without)
        hits += low <= math.sqrt(0.08) <= high
    assert hits / 4000 >= 0.94
