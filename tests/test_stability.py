"""Only stable orbits are the response: the Floquet multipliers of the frequency
response's orbits, checked against the closed form of the linear oscillator and against what a
perturbed run does, and the stability of every orbit the frequency response reports.

Stability is what a user relies on when reading a steady state, so it is shown here by marching
(the physics itself), not by the Jacobian that the harness uses to decide it: a reported orbit,
disturbed, must come back; a known unstable one, disturbed by 1e-9 ``Y``, must leave.
"""

from __future__ import annotations

import cmath
import json
import math
from pathlib import Path

import numpy as np
import pytest

from fmu_host import run_cli

from piezo_fmu_harness.datasets import open_dataset
from piezo_fmu_harness.periodic.drive import HarmonicDrive
from piezo_fmu_harness.periodic.band import rest_state, solve_point
from piezo_fmu_harness.periodic.steady_state import Settings

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
M, K, C = 1.0, 1000.0, 0.1
NATURAL = math.sqrt(K / M)
Y = 1e-3
NOMINAL = {"voltage_model": 1}  # the frequency response's default damper
#: A reduced band of the default frequency response (Y = 1 mm, the nominal damper): stable two-impact
#: orbits, their jumps, and the two-impact orbits that lose stability through a complex pair.
BAND = ("--ratio-min", 1.1, "--ratio-max", 1.35, "--count", 11)


@pytest.fixture(scope="module")
def band_study(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("band")
    assert run_cli("frequency-response", *BAND, "--jobs", 2, "--out", out, "--fmu", FMU, "--no-progress") == 0
    return out


def multipliers(record: dict) -> list[complex]:
    return [complex(re, im) for re, im in record["multipliers"]]


def departure_after(instance, values: dict, record: dict, kick, periods: int) -> list[float]:
    """Distances (m) from the orbit's section after each of ``periods`` orbits, started from the
    orbit's state plus ``kick``."""
    order = record["order"]
    drive = HarmonicDrive(instance, values, record["omega"], record["base_amplitude"], Settings().samples)
    drive.start(np.asarray(record["state"]) + kick, record["phase"])
    sections = drive.advance(periods * order)[order - 1::order]
    return [drive.distance(section, record["state"]) for section in sections]


# -- the linear limit, in closed form --------------------------------------------------------------

@pytest.mark.parametrize("ratio", [0.6, 1.0, 1.7])
def test_without_impacts_the_multipliers_are_those_of_the_oscillator_and_the_neutral_pair(instance, ratio):
    omega = ratio * NATURAL
    record = solve_point(instance, 0, {"d": 1.0}, omega, Y, Settings(), rest_state(), 0.0)
    assert record["settled"] and record["order"] == 1 and record["impacts_per_cycle"] == 0
    period = 2.0 * math.pi / omega
    # M x'' + C x' + K x = forcing: lambda = -C/(2M) +- i sqrt(K/M - (C/2M)^2), one period later exp(lambda T).
    decay, damped = C / (2 * M), math.sqrt(K / M - (C / (2 * M)) ** 2)
    expected = [cmath.exp(complex(-decay, sign * damped) * period) for sign in (1, -1)]
    found = multipliers(record)
    neutral = [mu for mu in found if mu == 1.0]
    oscillator = sorted((mu for mu in found if mu != 1.0), key=lambda mu: mu.imag)
    assert record["neutral_multipliers"] == 2 and len(neutral) == 2
    for mu, closed in zip(oscillator, sorted(expected, key=lambda mu: mu.imag)):
        assert abs(mu - closed) < 1e-6, (mu, closed)
    assert record["max_multiplier"] == pytest.approx(math.exp(-C * period / (2 * M)), abs=1e-6)
    assert record["verdict"] == "stable" and record["stable"] is True  # the neutral pair is not instability
    assert record["stability_margin"] == pytest.approx(1.0 - record["max_multiplier"])


# -- a known unstable orbit --------------------------------------------------------------------------

def test_the_three_impact_orbit_at_resonance_is_unstable_and_is_not_the_response(instance):
    record = solve_point(instance, 0, NOMINAL, NATURAL, Y, Settings(), rest_state(), 0.0)
    assert record["status"] == "ok"
    orbit = next(o for o in record["unstable_orbits"] if o["impacts_per_cycle"] == 3 and o["order"] == 1)
    assert orbit["amplitude"] == pytest.approx(7.40e-3, rel=2e-3)
    assert orbit["max_multiplier"] == pytest.approx(7.3, rel=0.01)
    assert orbit["verdict"] == "unstable" and orbit["stable"] is False
    # Marched from it, disturbed by 1e-9 Y, the machine leaves it within 20 periods: the distance
    # grows past 1e-4 Y, 1e5 times the kick.
    unstable = {**orbit, "omega": NATURAL, "base_amplitude": Y}
    direction = np.array([1.0, NATURAL, 0.0, 0.0])  # a kick of 1e-9 Y in p and in p'/w
    distances = departure_after(instance, NOMINAL, unstable, 1e-9 * Y * direction / np.array([1, NATURAL, 1, NATURAL]),
                                20)
    assert max(distances) > 1e-4 * Y, distances
    # The response reported at w_n is another motion: never this orbit.
    assert abs(record["amplitude"] - orbit["amplitude"]) > 1e-3 * orbit["amplitude"] or not record["settled"]
    if record["settled"]:
        assert record["stable"] and record["max_multiplier"] < 1.0
    else:
        assert record["verdict"] == "undecided" and record["order"] is None
        assert record["amplitude_min"] <= record["amplitude_max"] <= 2 * record["amplitude"]


# -- every reported orbit is stable --------------------------------------------------------------------

def test_every_orbit_the_band_reports_is_stable_by_its_multipliers(band_study):
    records = [json.loads(line) for line in (band_study / "points.jsonl").read_text().splitlines()]
    settled = [r for r in records if r["settled"]]
    impacting = [r for r in settled if r["impacts_per_cycle"] > 0]
    assert len(impacting) >= 5  # the band has stable impacting orbits, not only the linear ones
    for record in settled:
        assert all(abs(mu) <= 1.0 + 1e-3 for mu in multipliers(record) if mu != 1.0), record["index"]
        assert record["verdict"] == "stable" and record["multiplier_error"] < 1e-4
    # The band also met unstable orbits, and none of them is any point's response.
    met = [o for r in records for o in r["unstable_orbits"]]
    assert met and all(o["max_multiplier"] > 1.0 for o in met if o["verdict"] == "unstable")


def test_every_orbit_the_band_reports_comes_back_when_disturbed(band_study, instance):
    # Independent of the Jacobian: disturb each reported impacting orbit by 1e-4 Y in four random
    # directions and march on: it must come back closer than it was sent. The reported multiplier
    # only sets how long to wait (a quarter of the kick at its rate, at least 100 orbits).
    header = json.loads((band_study / "frequency_response.json").read_text())
    records = [json.loads(line) for line in (band_study / "points.jsonl").read_text().splitlines()]
    rng = np.random.default_rng(20)
    count = len(header["ratios"])
    checked = 0
    for record in records:
        if not record["settled"] or record["impacts_per_cycle"] == 0 or record["index"] >= 2 * count:
            continue
        for _ in range(4):
            kick = rng.normal(size=4)
            kick = 1e-4 * Y * kick / np.max(np.abs(kick)) / np.array([1, record["omega"], 1, record["omega"]])
            periods = max(100, math.ceil(math.log(0.25) / math.log(record["max_multiplier"])))
            distances = departure_after(instance, header["values"], record, kick, periods)
            assert distances[-1] < 0.5 * 1e-4 * Y, (record["index"], distances[::25])
        checked += 1
    assert checked >= 5


def test_unstable_orbits_met_in_the_band_leave_when_disturbed(band_study, instance):
    header = json.loads((band_study / "frequency_response.json").read_text())
    records = [json.loads(line) for line in (band_study / "points.jsonl").read_text().splitlines()]
    met = [(r, o) for r in records if r["index"] < 2 * len(header["ratios"]) for o in r["unstable_orbits"]
           if o["verdict"] == "unstable"]
    assert met
    for record, orbit in met[:6]:
        unstable = {**orbit, "omega": record["omega"], "base_amplitude": record["base_amplitude"]}
        kick = 1e-9 * Y * np.array([1.0, 0.0, 0.0, 0.0])
        periods = int(math.ceil(math.log(1e5) / math.log(orbit["max_multiplier"]))) + 20
        distances = departure_after(instance, header["values"], unstable, kick, periods)
        assert max(distances) > 1e-4 * Y, (record["index"], orbit["max_multiplier"], distances[-1])


# -- the results carry the multipliers ------------------------------------------------------------------

def test_the_results_carry_multipliers_verdicts_and_the_unstable_orbits(band_study):
    import pandas

    ds = open_dataset(band_study / "frequency_response.nc")
    assert ds.sizes["multiplier"] == 4 and ds.sizes["unstable"] > 0
    settled = ds["settled"].values == 1
    moduli = np.hypot(ds["multiplier_real"].values, ds["multiplier_imag"].values).max(axis=-1)
    assert np.all(moduli[settled] <= 1.0 + 1e-3)
    assert set(np.unique(ds["verdict"].values)) <= {"stable", "undecided"}
    assert np.all((ds["verdict"].values == "stable") == settled)
    assert np.all(ds["max_multiplier"].values[settled] < 1.0)
    assert np.all(ds["unstable_max_multiplier"].values[ds["unstable_verdict"].values == "unstable"] > 1.0)
    table = pandas.read_csv(band_study / "frequency_response.csv")
    assert {"max_multiplier", "stability_margin", "multiplier_error", "verdict", "multiplier_1_real",
            "multiplier_4_imag", "amplitude_min_m", "amplitude_max_m", "unstable_orbits"} <= set(table.columns)
    unstable = pandas.read_csv(band_study / "unstable_orbits.csv")
    assert len(unstable) == ds.sizes["unstable"]
    assert {"damper", "direction", "ratio", "amplitude_m", "max_multiplier", "verdict"} <= set(unstable.columns)
    summary = json.loads((band_study / "summary.json").read_text())
    assert summary["unstable_orbits_met"]["with the damper, sweep up"]["count"] + \
        summary["unstable_orbits_met"]["with the damper, sweep down"]["count"] == ds.sizes["unstable"]
