"""The random base excitation (piezo_fmu_harness.excitation): the generated input has the target
PSD and is Gaussian, its displacement is bounded with the oracle's variance, a realization's bits
do not depend on how it is taken, memory stays bounded, the envelope and the record path do what
they say, the oracle is accurate, fmpy replays the rows as a loop that sets them before each step
does, and every bad input is refused with its value and what is allowed.

Statistical checks compare against intervals derived here (chi-square for averaged periodograms,
the variance of a variance estimate from the PSD) at a stated level, with fixed seeds.
"""

from __future__ import annotations

import functools
import json
import math

import mpmath
import numpy as np
import pytest
from scipy import fft, signal, stats
from scipy.linalg import expm

from piezo_fmu_harness.excitation import (FRAME, CloughPenzien, Excitation, JenningsHousnerTsai, KanaiTajimi, Record,
                                          ShinozukaSato, TablePSD, WhiteNoise, oracle, read_replay_csv, replay_rows,
                                          write_replay_csv)
from piezo_fmu_harness.excitation.design import MAX_TAPS, TAPS_PER_CORNER, highpass_gain, highpass_sections

H = 0.01  # s: the tests' input step (fs = 100 Hz, so a band may reach 25 Hz)
FS = 1.0 / H
LEVEL = 0.01  # (m/s^2)^2/Hz
ALPHA = 1e-3  # the level of every statistical check (Bonferroni over its bins, windows or blocks)
SPECTRA = {
    "white": lambda: WhiteNoise(LEVEL, 1.0, 20.0),
    "kanai-tajimi": lambda: KanaiTajimi.soil("firm", LEVEL),
    "clough-penzien": lambda: CloughPenzien.soil("firm", LEVEL),
    "table": lambda: TablePSD([0.5, 2.0, 5.0, 10.0, 24.0], [1e-4, 4e-3, 4e-3, 1e-3, 1e-4]),
}
SEGMENT = 512  # Welch segment: 0.195 Hz bins
STEPS = 2**21  # after the high-pass has settled: 4096 segments, 8192 degrees of freedom a bin


def second_differences(y: np.ndarray) -> np.ndarray:
    """The base acceleration the FMU sees at the inner nodes, (y_{k+1} - 2 y_k + y_{k-1}) / h^2."""
    return (y[2:] - 2.0 * y[1:-1] + y[:-2]) / H**2


def settle(excitation) -> int:
    """Steps for the high-pass's start (from rest) to be forgotten: 20 / f_low seconds."""
    return int(20.0 / excitation.f_low / excitation.step)


@functools.lru_cache(maxsize=None)
def generated(kind: str):
    """One long realization of ``kind`` at the default f_low: (excitation, its acceleration after settling)."""
    excitation = Excitation(SPECTRA[kind](), H, seed=11)
    y, _ = excitation.stream(0).take(settle(excitation) + STEPS + 1)
    return excitation, second_differences(y)[settle(excitation):]


def autocovariance(excitation, lags: int) -> np.ndarray:
    """R(m), m = 0 .. lags - 1, of the acceleration the FMU sees: the inverse transform of its PSD."""
    n = 2**20
    density = excitation.density(np.arange(n // 2 + 1) * (FS / n))
    return FS * fft.irfft(density / 2.0, n)[:lags]


def expected_welch(excitation, segment: int = SEGMENT) -> np.ndarray:
    """The exact mean of scipy's Welch estimate (Hann, density scaling) for this PSD:
    2 / (fs sum w^2) sum_m c_w(m) R(m) exp(-2 pi i j m / L), c_w the window's autocorrelation."""
    w = signal.get_window("hann", segment)
    cw = np.correlate(w, w, "full")[segment - 1:]
    lagged = autocovariance(excitation, segment) * cw
    two_sided = np.concatenate((lagged, [0.0], lagged[:0:-1]))
    return 2.0 / (FS * np.sum(w * w)) * fft.rfft(two_sided).real[::2]


def welch(a: np.ndarray):
    f, p = signal.welch(a, fs=FS, window="hann", nperseg=SEGMENT, noverlap=0, detrend=False, scaling="density")
    return f, p, 2 * (a.size // SEGMENT)  # degrees of freedom of each bin: 2 per segment


def psd_agrees(excitation, a: np.ndarray, expected: np.ndarray) -> tuple[bool, int, str]:
    """Whether the Welch estimate of ``a`` lies, in every compared bin, inside the chi-square
    interval of its mean ``expected`` (Bonferroni over the bins at ALPHA). Compared: the bins from
    the third up where the mean is above 1e-3 of its largest, and not within two bins of a jump
    of the density (a band's edge), where the FIR's smoothed edge departs from the target's."""
    f, p, nu = welch(a)
    spectrum = excitation.source
    jumps = [x for x in (spectrum.lower, spectrum.upper) if x > 0.0]
    bins = (np.arange(f.size) >= 2) & (f < FS / 2) & (expected > 1e-3 * expected.max())
    for x in jumps:
        bins &= np.abs(f - x) > 2.0 * (FS / SEGMENT)
    m = int(bins.sum())
    lo, hi = stats.chi2.ppf(ALPHA / (2 * m), nu) / nu, stats.chi2.isf(ALPHA / (2 * m), nu) / nu
    ratio = p[bins] / expected[bins]
    worst = int(np.argmax(np.abs(np.log(ratio))))
    return bool(lo <= ratio.min() and ratio.max() <= hi), m, (
        f"{m} bins, interval [{lo:.4f}, {hi:.4f}], ratio {ratio.min():.4f} .. {ratio.max():.4f}, "
        f"worst at {f[bins][worst]:.3f} Hz")


# -- the spectra -----------------------------------------------------------------------------------

def test_the_spectra_have_the_stated_formulas_presets_levels_and_rms():
    f = np.array([0.0, 0.5, 2.0, 2.48, 7.0, 25.0, 26.0])
    r2 = (2 * np.pi * f / 15.6) ** 2
    kt = KanaiTajimi.soil("firm", LEVEL)
    assert np.allclose(kt.density(f), np.where(f <= 25.0, LEVEL * (1 + 1.44 * r2) / ((1 - r2) ** 2 + 1.44 * r2), 0.0),
                       rtol=1e-14, atol=0)
    cp = CloughPenzien.soil("soft", LEVEL)
    assert (cp.omega_g, cp.zeta_g, cp.omega_f, cp.zeta_f) == (5.0, 0.2, 0.5, 0.6)
    rf2 = (2 * np.pi * f / 0.5) ** 2
    assert np.allclose(cp.density(f), KanaiTajimi(LEVEL, 5.0, 0.2).density(f) * rf2**2 / ((1 - rf2) ** 2 + 1.44 * rf2),
                       rtol=1e-14, atol=0)
    white = WhiteNoise(LEVEL, 1.0, 20.0)
    assert white.rms() == pytest.approx(math.sqrt(LEVEL * 19.0), rel=1e-15)
    assert list(white.density([0.99, 1.0, 20.0, 20.01])) == [0.0, LEVEL, LEVEL, 0.0]
    table = SPECTRA["table"]()
    # log-log: halfway between 2 and 5 Hz on a log axis, between 10 and 24 Hz a power law
    assert table.density(math.sqrt(10.0)) == pytest.approx(4e-3, rel=1e-14)
    assert table.density(15.0) == pytest.approx(1e-3 * (15.0 / 10.0) ** (math.log(0.1) / math.log(2.4)), rel=1e-13)
    assert table.rms() == pytest.approx(math.sqrt(rms_by_quadrature(table)), rel=1e-9)
    for spectrum in (white, kt, cp, table):
        twice = spectrum.scaled(2 * spectrum.level)
        assert np.allclose(twice.density(f), 2 * spectrum.density(f), rtol=1e-14, atol=0)
        assert twice.rms() == pytest.approx(math.sqrt(2) * spectrum.rms(), rel=1e-9)
        described = json.loads(json.dumps(spectrum.describe()))
        assert described["kind"] == spectrum.kind and "one-sided" in described["convention"]
        assert described["unit"] == "(m/s^2)^2/Hz" and described["upper_Hz"] == spectrum.upper
    assert kt.peak() == pytest.approx(15.6 / (2 * np.pi) * math.sqrt(math.sqrt(1 + 8 * 0.36) - 1) / 1.2, rel=1e-6)


def rms_by_quadrature(spectrum) -> float:
    from scipy.integrate import quad

    points = spectrum.breakpoints()
    return sum(quad(lambda f: float(spectrum.density(f)), a, b, epsrel=1e-12)[0] for a, b in zip(points, points[1:]))


def test_the_table_reads_from_a_csv_file(tmp_path):
    path = tmp_path / "psd.csv"
    path.write_text("# a random-vibration profile\nfrequency_Hz,psd\n0.5, 1e-4\n2,4e-3\n\n5,4e-3\n10,1e-3\n24,1e-4\n")
    table = TablePSD.from_csv(path, upper=20.0)
    reference = SPECTRA["table"]()
    f = np.linspace(0.1, 30.0, 300)
    assert np.array_equal(table.density(f), np.where(f <= 20.0, reference.density(f), 0.0))
    assert table.describe()["source"] == str(path)


# -- the PSD and the distribution ------------------------------------------------------------------

@pytest.mark.parametrize("kind", list(SPECTRA))
def test_the_generated_acceleration_has_the_target_psd(kind):
    excitation, a = generated(kind)
    agrees, bins, report = psd_agrees(excitation, a, expected_welch(excitation))
    assert agrees, report
    assert bins >= 80, report  # the band, 1 to 20 Hz at least, is compared


@pytest.mark.parametrize("wrong", [dict(level=1.1 * LEVEL), dict(omega_g=1.05 * 15.6), dict(zeta_g=0.55)],
                         ids=["level+10%", "omega_g+5%", "zeta_g-0.05"])
def test_the_psd_comparison_fails_against_a_wrong_target(wrong):
    excitation, a = generated("kanai-tajimi")
    target = dict(level=LEVEL, omega_g=15.6, zeta_g=0.6) | wrong
    wrong_excitation = Excitation(KanaiTajimi(**target), H, f_low=excitation.f_low)
    agrees, _, report = psd_agrees(excitation, a, expected_welch(wrong_excitation))
    assert not agrees, report


@pytest.mark.parametrize("kind", ["white", "kanai-tajimi"])
def test_the_generated_acceleration_is_gaussian(kind):
    excitation, a = generated(kind)
    # Every 50th sample (0.5 s apart: the autocorrelation there is below 0.01), standardised by the oracle's RMS.
    rho = autocovariance(excitation, 51)
    assert abs(rho[50] / rho[0]) < 0.01
    x = a[::50] / math.sqrt(oracle.acceleration_variance(excitation))
    n = x.size
    z = stats.norm.isf(ALPHA / 2)
    assert abs(stats.skew(x)) < z * math.sqrt(6.0 / n), stats.skew(x)
    assert abs(stats.kurtosis(x)) < z * math.sqrt(24.0 / n), stats.kurtosis(x)
    # Against the fully specified N(0, 1): Kolmogorov-Smirnov and Cramer-von Mises.
    assert stats.kstest(x, "norm").pvalue > ALPHA
    assert stats.cramervonmises(x, "norm").pvalue > ALPHA


# -- the displacement ------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def displaced():
    """A long realization with a faster high-pass (f_low = 0.5 Hz): its nodes after settling."""
    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), H, f_low=0.5, seed=3)
    y, _ = excitation.stream(0).take(settle(excitation) + STEPS)
    return excitation, y[settle(excitation):]


def variance_interval(psd, excitation, n: int, z: float) -> float:
    """z times the standard deviation of the mean square of n samples of a zero-mean Gaussian
    process of one-sided PSD ``psd``: sqrt(fs / n int psd^2 df)."""
    return z * math.sqrt(FS / n * oracle.variance(lambda f: psd(f) ** 2, excitation))


def test_the_displacement_is_bounded_and_has_the_oracles_variance():
    excitation, y = displaced()
    expected = oracle.base_displacement_variance(excitation)
    psd = functools.partial(oracle.base_displacement_psd, excitation)
    blocks = 8
    z = stats.norm.isf(ALPHA / (2 * (blocks + 1)))
    size = y.size // blocks
    for k in range(blocks):  # no drift: every eighth of the record has the same variance
        block = y[k * size:(k + 1) * size]
        assert abs(np.mean(block**2) - expected) < variance_interval(psd, excitation, size, z), (k, np.mean(block**2))
    assert abs(np.mean(y**2) - expected) < variance_interval(psd, excitation, y.size, z)
    assert np.max(np.abs(y)) < 6.0 * math.sqrt(expected)


def test_a_linear_oscillator_on_the_generated_base_has_the_oracles_variance():
    # The oscillator on the first-order hold, exactly: its relative velocity jumps by -(v_k - v_{k-1})
    # at each node and it moves freely between nodes (zeta = 0.05 here, for a short correlation time).
    excitation, y = displaced()
    M, K, C = 1.0, 1000.0, 2 * 0.05 * math.sqrt(1000.0)
    v = np.diff(y) / H
    jumps = np.diff(v, prepend=0.0)
    transition = expm(np.array([[0.0, 1.0], [-K / M, -C / M]]) * H)
    num, den = signal.ss2tf(transition, transition @ np.array([[0.0], [-1.0]]), np.array([[1.0, 0.0]]), [[0.0]])
    x = signal.lfilter(num[0], den, jumps)[settle(excitation):]
    expected = oracle.relative_displacement_variance(excitation, M, K, C)
    psd = functools.partial(oracle.relative_displacement_psd, excitation, M=M, K=K, C=C)
    assert abs(np.mean(x**2) - expected) < variance_interval(psd, excitation, x.size, stats.norm.isf(ALPHA / 2))


def test_the_base_acceleration_the_fmu_sees_is_the_high_passed_record(tmp_path):
    # A record is taken as it is: the second differences of the nodes are its high-passed samples,
    # by scipy's own Butterworth (not the generator's sections).
    rng = np.random.default_rng(0)
    record = Record(H, rng.standard_normal(5000))
    excitation = Excitation(record, f_low=0.3)
    y, _ = excitation.stream(0).take(5000)
    b, a = signal.butter(4, 0.3, btype="highpass", fs=FS)
    expected = signal.lfilter(b, a, record.acceleration)
    seen = np.concatenate(([y[1] / H**2], second_differences(y)))  # y_{-1} = y_0 = 0
    assert np.max(np.abs(seen - expected)) < 1e-9 * np.max(np.abs(expected))
    assert y[0] == 0.0


def test_a_recorded_sinusoid_gives_the_expected_displacement_and_comes_back_to_rest(tmp_path):
    f0, amplitude, f_low = 2.0, 1.5, 0.2
    t = np.arange(20000) * H
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack((t + 3.0, amplitude * np.sin(2 * np.pi * f0 * t))), delimiter=",",
               header="time_s,acceleration_m_per_s2", comments="", fmt="%.17g")
    excitation = Excitation(Record.from_csv(path), f_low=f_low)
    assert excitation.step == pytest.approx(H, rel=1e-12)
    y, _ = excitation.stream(0).take(40000)
    # The steady state of y_{k+1} - 2 y_k + y_{k-1} = h^2 HP a_k: gain -h^2 / (4 sin^2(theta/2)) HP(theta).
    theta = 2 * np.pi * f0 * H
    _, response = signal.freqz(*signal.butter(4, f_low, btype="highpass", fs=FS), worN=[f0], fs=FS)
    gain = -H**2 / (4 * math.sin(theta / 2) ** 2) * response[0]
    k = np.arange(10000, 20000)  # after 100 s: the high-pass's start has died out
    expected = amplitude * abs(gain) * np.sin(theta * k + np.angle(gain))
    assert np.max(np.abs(y[k] - expected)) < 1e-7 * amplitude * abs(gain)
    assert abs(gain) == pytest.approx(1 / (2 * np.pi * f0) ** 2, rel=2e-3)  # the continuous 1/w^2
    assert np.max(np.abs(y[-1000:])) < 1e-9 * amplitude * abs(gain)  # 200 s after the record: at rest again


# -- bits and memory -------------------------------------------------------------------------------

def test_a_realizations_bits_do_not_depend_on_blocks_chunks_or_workers():
    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), H, seed=5)
    count = 2 * FRAME + 7000
    y, v = excitation.stream(3).take(count)
    for block in (1, 7, 1000, 12345):
        stream = excitation.stream(3)
        nodes, slopes = [stream.take(0)[0]], []
        for begin in range(0, count, block):
            yy, vv = stream.take(min(block, count - begin))
            assert yy[0] == nodes[-1][-1]  # a block starts at the last node of the previous one
            nodes.append(yy[1:])
            slopes.append(vv)
        assert np.array_equal(np.concatenate(nodes), y) and np.array_equal(np.concatenate(slopes), v), block
    together = excitation.chunk(range(6))
    first = together.take(10000)
    rest = together.take(count - 10000)
    ys = np.concatenate((first[0], rest[0][1:]))
    assert np.array_equal(ys[:, 3], y) and np.array_equal(np.concatenate((first[1], rest[1]))[:, 3], v)
    for split in ([0, 1, 2], [3, 4, 5]), ([5, 3], [0, 4, 1, 2]):  # as workers would share the realizations
        for part in split:
            yy, _ = excitation.chunk(part).take(count)
            for j, r in enumerate(part):
                assert np.array_equal(yy[:, j], ys[:, r]), (split, r)
    assert not np.array_equal(ys[:, 2], ys[:, 3])
    assert not np.array_equal(Excitation(KanaiTajimi.soil("firm", LEVEL), H, seed=6).stream(3).take(count)[0], y)


def test_a_long_record_keeps_the_streams_buffers_bounded():
    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), H, seed=1)
    stream, chunk = excitation.stream(0), excitation.chunk([1, 2])
    seen, peak = set(), 0.0
    for _ in range(12):  # 3 million steps
        y, _ = stream.take(250_000)
        chunk.take(1_000)
        peak = max(peak, float(np.max(np.abs(y))))
        seen.add(tuple(stream.buffers.items()))
    assert seen == {(("noise_history", excitation.taps - 1), ("frame_nodes", FRAME), ("filter_state", 4))}
    assert all(s.buffers == stream.buffers for s in chunk.streams)
    assert stream.position == 3_000_000
    assert peak < 8.0 * math.sqrt(oracle.base_displacement_variance(excitation))


# -- the envelope ----------------------------------------------------------------------------------

@pytest.mark.parametrize("envelope", [JenningsHousnerTsai(2.0, 5.0, 0.5), ShinozukaSato(0.3, 1.5)],
                         ids=["jennings-housner-tsai", "shinozuka-sato"])
def test_the_variance_follows_the_envelope_squared(envelope):
    excitation = Excitation(WhiteNoise(LEVEL, 1.0, 20.0), H, f_low=0.5, envelope=envelope, seed=2)
    realizations, steps, window = 200, 1500, 50
    y, _ = excitation.chunk(range(realizations)).take(steps)
    a = (y[2:] - 2 * y[1:-1] + y[:-2]) / H**2  # nodes 1 .. steps - 1
    e2 = envelope(np.arange(1, steps) * H) ** 2
    rho = autocovariance(excitation, window)
    rho = rho / rho[0]
    sigma2 = oracle.acceleration_variance(excitation)
    windows = [slice(k, k + window) for k in range(0, steps - 1 - window + 1, window)]
    windows = [w for w in windows if e2[w].sum() > 1e-3 * window]
    lags = np.abs(np.subtract.outer(np.arange(window), np.arange(window)))
    for w in windows:
        weights = e2[w]
        ratio = np.sum(a[w] ** 2) / (realizations * sigma2 * weights.sum())
        variance = 2 * weights @ (rho[lags] ** 2) @ weights / (realizations * weights.sum() ** 2)
        nu = 2.0 / variance  # ratio ~ chi2(nu) / nu (moments matched)
        lo = stats.chi2.ppf(ALPHA / (2 * len(windows)), nu) / nu
        hi = stats.chi2.isf(ALPHA / (2 * len(windows)), nu) / nu
        assert lo < ratio < hi, (w, ratio, lo, hi)
    assert len(windows) >= 20


# -- the filters and the oracle --------------------------------------------------------------------

def test_the_high_pass_gain_and_the_shaping_fir_are_what_the_design_says():
    f_low = 0.1
    f = np.linspace(0.01, 49.0, 500)
    _, response = signal.sosfreqz(highpass_sections(f_low, H), worN=f, fs=FS)
    assert np.allclose(np.abs(response) ** 2, highpass_gain(f, f_low, H), rtol=1e-9, atol=1e-15)
    b, a = signal.butter(4, f_low, btype="highpass", fs=FS)
    assert np.allclose(np.abs(signal.freqz(b, a, worN=f, fs=FS)[1]) ** 2, highpass_gain(f, f_low, H), rtol=1e-6)
    # The FIR's response on its design grid is the target's magnitude smoothed over three points.
    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), H, f_low=f_low)
    taps = excitation.taps
    assert taps == 8000 and TAPS_PER_CORNER * FS / f_low == taps
    from piezo_fmu_harness.excitation.design import design_fir

    fir = design_fir(excitation.source.density, H, taps)
    grid = np.arange(taps // 2 + 1) * FS / taps
    target = np.sqrt(excitation.source.density(grid) * FS / 2)
    smoothed = 0.5 * target[1:-1] + 0.25 * (target[:-2] + target[2:])
    assert np.allclose(np.abs(fft.rfft(fir))[1:-1], smoothed, rtol=1e-10, atol=1e-12 * target.max())


def nominal_integrand(excitation, M, K, C):
    """|H|^2 G |HP|^2 in mpmath, from the formulas, not from the package's functions."""
    h, f_low = excitation.step, excitation.f_low
    spectrum = excitation.source

    def integrand(f):
        w = 2 * mpmath.pi * f
        if isinstance(spectrum, WhiteNoise):
            g = mpmath.mpf(spectrum.level) if spectrum.fmin <= f <= spectrum.fmax else mpmath.mpf(0)
        else:
            r2 = (w / spectrum.omega_g) ** 2
            g = spectrum.level * (1 + 4 * spectrum.zeta_g**2 * r2) / ((1 - r2) ** 2 + 4 * spectrum.zeta_g**2 * r2)
        hp = 1 / (1 + (mpmath.tan(mpmath.pi * f_low * h) / mpmath.tan(mpmath.pi * f * h)) ** 8)
        return g * hp / ((K / M - w**2) ** 2 + (w * C / M) ** 2)

    return integrand


@pytest.mark.parametrize("spectrum", [KanaiTajimi.soil("firm", LEVEL), WhiteNoise(LEVEL, 0.5, 20.0)],
                         ids=["kanai-tajimi", "white"])
def test_the_oracle_variance_is_accurate_at_the_nominal_dampers_sharp_resonance(spectrum):
    M, K, C = 1.0, 1000.0, 0.1  # the core's defaults: zeta = 0.0016
    excitation = Excitation(spectrum, 0.004)
    ours = oracle.relative_displacement_variance(excitation, M, K, C)
    mpmath.mp.dps = 30
    fn, width = math.sqrt(K / M) / (2 * math.pi), C / M / (4 * math.pi)
    points = {1e-9, *(excitation.f_low * c for c in (0.5, 1, 2, 4)), *spectrum.breakpoints(), spectrum.upper,
              *(fn + s * width * d for s in (-1, 1) for d in (300, 100, 30, 10, 3, 1, 0.3)), fn}
    points = sorted(p for p in points if 0.0 < p <= spectrum.upper)
    reference = mpmath.quad(nominal_integrand(excitation, M, K, C), points)
    assert abs(ours / float(reference) - 1) < 1e-9, (ours, reference)
    resonant = spectrum.density(fn) * highpass_gain(fn, excitation.f_low, 0.004) * M**2 / (4 * C * K)
    assert ours == pytest.approx(resonant, rel=0.05)  # the white-noise estimate G(f_n) / (8 zeta w_n^3)


def test_the_excitation_describes_itself_as_json():
    excitation = Excitation(CloughPenzien.soil("medium", LEVEL), 0.004, envelope=ShinozukaSato(0.2, 1.0), seed=9)
    described = json.loads(json.dumps(excitation.describe()))
    assert described["highpass"]["order"] == 4 and described["highpass"]["corner_Hz"] == 0.1
    assert described["shaping_fir"]["window"].startswith("Hann") and described["shaping_fir"]["frame_steps"] == FRAME
    assert described["envelope"]["kind"] == "shinozuka-sato" and described["seed"] == 9
    assert described["source"]["kind"] == "clough-penzien" and described["step_s"] == 0.004


# -- the replay ------------------------------------------------------------------------------------

def test_the_replay_rows_are_the_inputs_at_each_steps_start_and_read_back_to_the_bits(tmp_path):
    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), 0.004, seed=4)
    rows = replay_rows(excitation, 2, 3000)
    y, v = excitation.stream(2).take(3000)
    assert rows.dtype.names == ("time", "base_displacement", "base_velocity") and rows.size == 3000
    assert np.array_equal(rows["base_displacement"], y[:-1]) and np.array_equal(rows["base_velocity"], v)
    assert np.array_equal(rows["time"], np.array([k * 0.004 for k in range(3000)]))  # k h, as fmpy computes it
    back = read_replay_csv(write_replay_csv(tmp_path / "replay.csv", rows))
    assert back.dtype == rows.dtype and all(np.array_equal(back[name], rows[name]) for name in rows.dtype.names)


def test_fmpy_replays_the_rows_as_a_loop_that_sets_them_before_each_step():
    from fmpy import simulate_fmu

    from piezo_fmu_harness import fmus
    from piezo_fmu_harness.fmu import FmuModel, Instance, discard

    h, steps = 0.004, 1000
    rows = replay_rows(Excitation(KanaiTajimi.soil("firm", 5 * LEVEL), h, seed=3), 0, steps)
    values = {"p0": 0.0, "q0": 0.0}  # the damper at rest with the base
    replayed = simulate_fmu(str(fmus.path()), start_values=values, input=rows, stop_time=steps * h, output_interval=h,
                            output=["main_displacement", "impact_count"])
    model = FmuModel(fmus.path())
    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        instance.start(values, inputs={"base_displacement": rows["base_displacement"][0],
                                       "base_velocity": rows["base_velocity"][0]})
        refs = [model.inputs["base_displacement"], model.inputs["base_velocity"]]
        looped = [instance.read(["main_displacement"])["main_displacement"]]
        for k in range(steps):
            instance.fmu.setReal(refs, [rows["base_displacement"][k], rows["base_velocity"][k]])
            instance.fmu.doStep(k * h, (k + 1) * h - k * h)
            looped.append(instance.read(["main_displacement"])["main_displacement"])
    finally:
        instance.free()
        discard(unzipdir)
    assert replayed["impact_count"][-1] > 10  # the impacts make the motion sensitive to every bit of the input
    assert np.array_equal(np.array(looped), replayed["main_displacement"])


# -- refusals --------------------------------------------------------------------------------------

def record_file(tmp_path, text):
    path = tmp_path / "record.csv"
    path.write_text(text)
    return path


def table_file(tmp_path, text):
    path = tmp_path / "table.csv"
    path.write_text(text)
    return path


WHITE = WhiteNoise(LEVEL, 1.0, 20.0)
RECORD = Record(H, np.ones(100))
REFUSALS = {
    "negative level": (lambda p: WhiteNoise(-1.0, 1.0, 20.0), ["level = -1.0", "allowed range (0, inf) (m/s^2)^2/Hz"]),
    "empty band": (lambda p: WhiteNoise(LEVEL, 5.0, 2.0), ["fmin = 5.0 Hz", "allowed range (0, 2) Hz"]),
    "band from zero": (lambda p: WhiteNoise(LEVEL, 0.0, 20.0), ["fmin = 0.0 Hz", "allowed range (0, 20) Hz"]),
    "infinite fmax": (lambda p: WhiteNoise(LEVEL, 1.0, math.inf), ["fmax = inf", "not finite", "(0, inf) Hz"]),
    "nan omega_g": (lambda p: KanaiTajimi(LEVEL, math.nan, 0.6), ["omega_g = nan", "not finite", "(0, inf) rad/s"]),
    "zero zeta_g": (lambda p: KanaiTajimi(LEVEL, 15.6, 0.0), ["zeta_g = 0.0", "allowed range (0, inf)"]),
    "negative cut": (lambda p: KanaiTajimi(LEVEL, 15.6, 0.6, upper=-3.0), ["upper = -3.0 Hz", "(0, inf) Hz"]),
    "negative omega_f": (lambda p: CloughPenzien(LEVEL, 15.0, 0.6, omega_f=-1.0), ["omega_f = -1.0 rad/s", "(0, inf)"]),
    "text zeta_f": (lambda p: CloughPenzien(LEVEL, 15.0, 0.6, zeta_f="a"),
                    ["zeta_f = 'a' is not a number", "(0, inf)"]),
    "unknown soil": (lambda p: KanaiTajimi.soil("rock", LEVEL), ["soil = 'rock'", "firm, medium, soft"]),
    "negative psd": (lambda p: TablePSD([1.0, 2.0], [1e-3, -1e-3]), ["row 1", "PSD = -0.001", "(0, inf)"]),
    "unsorted table": (lambda p: TablePSD([2.0, 1.0], [1.0, 1.0]), ["row 1", "frequency = 1.0 Hz", "(2, inf) Hz"]),
    "one row": (lambda p: TablePSD([1.0], [1.0]), ["1 rows", "at least 2"]),
    "cut past the table": (lambda p: TablePSD([1.0, 3.0], [1.0, 1.0], upper=5.0), ["upper = 5.0 Hz", "(1, 3] Hz"]),
    "negative scaled level": (lambda p: WHITE.scaled(-2.0), ["level = -2.0", "(0, inf)"]),
    "three columns": (lambda p: TablePSD.from_csv(table_file(p, "f,g\n1,2,3\n")),
                      ["line 2", "3 columns", "exactly two"]),
    "text in a row": (lambda p: TablePSD.from_csv(table_file(p, "1,2\n2,x\n")), ["line 2", "'2,x'", "numeric"]),
    "unsorted file": (lambda p: TablePSD.from_csv(table_file(p, "1,2\n3,2\n2,2\n")), ["line 3", "frequency = 2.0 Hz",
                                                                                      "(3, inf) Hz"]),
    "negative psd in a file": (lambda p: TablePSD.from_csv(table_file(p, "1,2\n3,-1\n")), ["line 2", "PSD = -1.0"]),
    "one row in a file": (lambda p: TablePSD.from_csv(table_file(p, "f,g\n1,2\n")), ["1 data rows", "at least 2"]),
    "no file": (lambda p: TablePSD.from_csv(p / "missing.csv"), ["missing.csv", "cannot be read"]),
    "uneven record": (lambda p: Record.from_csv(record_file(p, "0,1\n0.01,1\n0.02,1\n0.04,1\n0.05,1\n")),
                      ["line 4", "from 0.02 s to 0.04 s", "the record's step 0.01 s"]),
    "record backwards": (lambda p: Record.from_csv(record_file(p, "1,1\n0,1\n")), ["line 2", "do not increase",
                                                                                  "uniform, positive step"]),
    "zero step": (lambda p: Excitation(WHITE, 0.0), ["step = 0.0 s", "allowed range (0, inf) s"]),
    "no step": (lambda p: Excitation(WHITE), ["step = None is not a number", "(0, inf) s"]),
    "band above the step": (lambda p: Excitation(WhiteNoise(LEVEL, 1.0, 30.0), H),
                            ["upper = 30 Hz", "step = 0.01 s", "upper <= fs/4 = 25 Hz", "at most 0.00833333 s"]),
    "f_low in the band": (lambda p: Excitation(WHITE, H, f_low=0.8),
                          ["f_low = 0.8 Hz", "allowed range [0.00305176, 0.5] Hz", "band's start 1 Hz"]),
    "zero f_low": (lambda p: Excitation(WHITE, H, f_low=0.0), ["f_low = 0.0 Hz", "[0.00305176, 0.5] Hz"]),
    "negative seed": (lambda p: Excitation(WHITE, H, seed=-1), ["seed = -1", "whole numbers from 0 up"]),
    "fractional seed": (lambda p: Excitation(WHITE, H, seed=1.5), ["seed = 1.5 is not a whole number"]),
    "not an envelope": (lambda p: Excitation(WHITE, H, envelope="x"), ["envelope = 'x'", "JenningsHousnerTsai"]),
    "not a source": (lambda p: Excitation(3, H), ["source = 3", "a spectrum", "Record"]),
    "second realization of a record": (lambda p: Excitation(RECORD).stream(1), ["realization = 1", "from 0 to 0"]),
    "record resampled": (lambda p: Excitation(RECORD, step=0.02), ["step = 0.02 s differs", "record's step 0.01 s"]),
    "record f_low": (lambda p: Excitation(RECORD, f_low=30.0), ["f_low = 30.0 Hz", "[0.00305176, 25] Hz"]),
    "negative count": (lambda p: Excitation(WHITE, H).stream(0).take(-1), ["count = -1", "from 0 up"]),
    "negative realization": (lambda p: Excitation(WHITE, H).chunk([0, -2]), ["realization = -2", "from 0 up"]),
    "rise after plateau": (lambda p: JenningsHousnerTsai(3.0, 1.0, 1.0), ["t2 = 1.0 s", "[3, inf) s", "t2 >= t1"]),
    "no decay": (lambda p: JenningsHousnerTsai(1.0, 3.0, 0.0), ["c = 0.0 1/s", "(0, inf) 1/s"]),
    "slow rise": (lambda p: ShinozukaSato(1.0, 0.5), ["b2 = 0.5 1/s", "(1, inf) 1/s", "b2 > b1"]),
    "undamped oscillator": (lambda p: oracle.relative_displacement_variance(Excitation(WHITE, H), 1.0, 1e3, 0.0),
                            ["C = 0.0 N.s/m", "(0, inf) N.s/m", "undamped"]),
    "no psd of a record": (lambda p: Excitation(RECORD).density(1.0), ["recorded excitation has no PSD",
                                                                       "allowed: an excitation of a spectrum"]),
    "no replay steps": (lambda p: replay_rows(Excitation(WHITE, H), 0, 0), ["steps = 0", "from 1 up"]),
    "slowest high-pass": (lambda p: Excitation(WHITE, H, f_low=TAPS_PER_CORNER * FS / MAX_TAPS / 2),
                          ["f_low = 0.0015258789", "[0.00305176, 0.5] Hz"]),
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_every_bad_input_is_refused_with_its_value_and_what_is_allowed(case, tmp_path):
    make, words = REFUSALS[case]
    with pytest.raises(ValueError) as refused:
        make(tmp_path)
    message = str(refused.value)
    assert "allowed" in message, message
    for word in words:
        assert word in message, (word, message)


@pytest.mark.parametrize("M, K, C", [(1.0, 3.679136818588394e-195, 0.1), (1.0, 1000.0, 1e-300), (1e-300, 1e-170, 1e-300)])
def test_the_oracles_psd_holds_where_the_squares_of_its_denominator_leave_double_range(M, K, C):
    """A spring or a damper at the edges of the FMU's ranges: ``|H|^2 G`` is the quotient at 50
    digits (mpmath) wherever that is a double, 0 where the input's density is (at 0 Hz, the
    high-pass), and no numpy warning is raised (its squares underflow or overflow there)."""
    import warnings

    excitation = Excitation(KanaiTajimi.soil("firm", LEVEL), 0.004)
    # beside the resonance (1.01 f_n): at it, a damping of 1e-300 leaves the quotient to the rounding of f
    frequencies = np.array([0.0, 1e-200, 1e-80, 1e-3, 0.1, 1.01 * math.sqrt(K / M) / (2 * math.pi), 1.0, 24.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = oracle.relative_displacement_psd(excitation, frequencies, M, K, C)
    with mpmath.workdps(50):
        for f, value in zip(frequencies, got):
            density = mpmath.mpf(float(excitation.density(f)))
            w = 2 * mpmath.pi * mpmath.mpf(f)
            exact = (density / ((mpmath.mpf(K) / M - w * w) ** 2 + (w * mpmath.mpf(C) / M) ** 2) if density
                     else mpmath.mpf(0))
            if exact > np.finfo(float).max:
                assert value == math.inf, (f, value)
            else:
                assert abs(value - exact) <= 1e-13 * exact + np.finfo(float).tiny, (f, value, exact)
