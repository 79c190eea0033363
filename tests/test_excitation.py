"""The random base excitation (piezo_fmu_harness.excitation): the spectra have the stated formulas,
presets, levels and RMS, a table reads from its CSV file, and every bad input is refused with its
value and what is allowed.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from piezo_fmu_harness.excitation import (CloughPenzien, JenningsHousnerTsai, KanaiTajimi, ShinozukaSato, TablePSD,
                                          WhiteNoise)

LEVEL = 0.01  # (m/s^2)^2/Hz
SPECTRA = {
    "table": lambda: TablePSD([0.5, 2.0, 5.0, 10.0, 24.0], [1e-4, 4e-3, 4e-3, 1e-3, 1e-4]),
}


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


# -- refusals --------------------------------------------------------------------------------------

def table_file(tmp_path, text):
    path = tmp_path / "table.csv"
    path.write_text(text)
    return path


WHITE = WhiteNoise(LEVEL, 1.0, 20.0)
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
    "rise after plateau": (lambda p: JenningsHousnerTsai(3.0, 1.0, 1.0), ["t2 = 1.0 s", "[3, inf) s", "t2 >= t1"]),
    "no decay": (lambda p: JenningsHousnerTsai(1.0, 3.0, 0.0), ["c = 0.0 1/s", "(0, inf) 1/s"]),
    "slow rise": (lambda p: ShinozukaSato(1.0, 0.5), ["b2 = 0.5 1/s", "(1, inf) 1/s", "b2 > b1"]),
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
