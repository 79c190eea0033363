"""Global stability across a band: at each frequency, how likely each motion is.

At each of ``--count`` frequencies from ``--ratio-min`` to ``--ratio-max`` times ``sqrt(K/M)``,
``--starts`` random starts are marched on the batch engine (``piezo_fmu.solver.batch``) to the
motion each one's trajectory reaches (the rule of ``piezo_fmu.solver.batch.attractors.settle``), and the
fraction of the starts on each attractor is its share. This answers a designer's question that
continuation, which follows one orbit at a time, cannot: how likely the good motion is.

**The starts** (seeded by ``--seed``, the same draws at every frequency so that the shares change
with the frequency, not with the draw): ``p0`` uniform in ``[-S, S]``, ``p0'`` uniform in
``[-S w_n, S w_n]`` (``S`` = ``--span``, the gap ``d`` by default), the impact mass at rest
(``q0' = 0``) anywhere in the gap, uniformly. A start whose impact mass moves would end on the motion
without impacts with probability 0 (a drifting impact mass always reaches a barrier), so at rest
is where the question is open.

**Names across the band.** The attractors of each frequency are matched to the previous
frequency's by kind (order and impacts per cycle, or the class of a motion that is not periodic)
and the nearest amplitude (:func:`piezo_fmu_harness.starts.attractors.track_names`), so each
keeps one name across the band.

The frequencies are grouped into chunks of the sweep engine, each chunk one batch, appended to
``points.jsonl`` as it finishes (``--resume``). **The FMU checks the answer**: one start of every
attractor across the band (by its name), the one that reached it soonest, and ``--confirm`` random
starts more (:mod:`piezo_fmu_harness.starts.fmu_checks`) are marched through the FMU, which must
reach the same attractor (:mod:`piezo_fmu_harness.starts.destination`).

**A start ends where its trajectory ends**. ``--max-cycles`` is a budget, not a
verdict: a start not seen reaching an orbit within it is **undecided**, reported with its share,
never folded into an attractor. At each frequency the survival curve of the starts (the share
still unresolved after ``t`` periods) is fitted (:mod:`piezo_fmu_harness.starts.transients`):
the **mean transient lifetime** with its 95% interval, and the plateau. Undecided starts are called
chaotic (or quasi-periodic) only where the plateau is shown and their own exponent says so
(:func:`piezo_fmu_harness.starts.attractors.verdict`).

Files: ``fractions.nc`` (the fraction of each attractor over frequency, adding to 1 at every
frequency, with its 95% interval; each attractor's amplitude and impacts per cycle; the undecided
share, the mean transient lifetime with its interval, the plateau and the survival curve over
frequency), ``fractions.csv``, ``transients.csv`` (a row a frequency; each column with its unit),
``summary.json`` (the budget, the shares and what stayed undecided at each frequency, the checks, the
times of the marching and of the checks), ``fractions.png`` (the shares
stacked over frequency, and each attractor's amplitude), ``transients.png`` (the mean lifetime over
frequency, and the survival curves of a few frequencies).

This study reads the simulation core's batch engine besides the FMU, which checks it: the one
exception, with the basins and the bifurcation diagram, to the harness's rule that it reads
nothing but the FMU.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ...starts.attractors import merge, shares, track_names
from ...starts.fmu_checks import confirm, tally
from ...starts.chunks import check_chunk, chunk_size
from ...store import Damaged, open_folder, require, within, write_json

HEADER_FILE = "fractions.json"
#: The files a fractions study writes besides its header and ``points.jsonl``.
FILES = ("fractions.nc", "fractions.csv", "transients.csv", "summary.json", "fractions.png", "transients.png")
#: The band's defaults: 61 frequencies over 0.5 to 2 sqrt(K/M), a budget of 6000 periods a start
#: (at 1.25 w_n the last of 500 starts reaches its orbit at period 5940).
DEFAULTS = {"ratios": (0.5, 2.0), "count": 61, "max_cycles": 6000, "fewest": 1}
DEFAULT_STARTS = 500
#: FMU checks of random starts besides one of every attractor across the band (docs/harness.md: the
#: checking then takes no longer than the marching).
DEFAULT_CONFIRM = 2


@dataclass(frozen=True)
class FractionSpec:
    """One fractions study (SI)."""

    ratios: tuple
    natural: float
    amplitudes: tuple   # Y (m) at each frequency
    values: dict
    starts: int
    span: float         # m
    seed: int
    samples: int = 64
    tolerance: float = 1e-6
    max_cycles: int = DEFAULTS["max_cycles"]
    device: str = "cpu"
    confirm: int = DEFAULT_CONFIRM

    @property
    def omegas(self) -> np.ndarray:
        return np.array(self.ratios) * self.natural

    def draws(self) -> np.ndarray:
        """``(starts, 3)`` uniform draws in [-1, 1]: ``p0``, ``p0'`` and the impact mass's place."""
        return np.random.default_rng(self.seed).uniform(-1.0, 1.0, (self.starts, 3))

    def states(self) -> np.ndarray:
        """The starts ``(p0, p0', q0, q0')``, the same at every frequency."""
        u = self.draws()
        p0 = self.span * u[:, 0]
        half_gap = 0.5 * self.values["d"]
        return np.stack([p0, self.span * self.natural * u[:, 1], p0 + half_gap * u[:, 2], np.zeros(self.starts)], axis=1)

    def chunks(self) -> list[list[int]]:
        """The frequencies of each chunk (:func:`piezo_fmu_harness.starts.chunks.chunk_size` starts
        or a little more, whole frequencies)."""
        size = max(1, -(-chunk_size(self.starts * len(self.ratios)) // self.starts))
        return [list(range(k, min(k + size, len(self.ratios)))) for k in range(0, len(self.ratios), size)]

    def to_dict(self) -> dict:
        return asdict(self)


def settle_chunk(instance, spec: dict, number: int, frequencies: list[int]) -> dict:
    """A task: the starts at the frequencies ``frequencies``, one batch, to where they go."""
    from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, damper, settle

    begin = time.perf_counter()
    study = FractionSpec(**{**spec, "ratios": tuple(spec["ratios"]), "amplitudes": tuple(spec["amplitudes"])})
    drives = [HarmonicHold(float(study.omegas[f]), study.amplitudes[f], 0.0, study.samples) for f in frequencies]
    states = study.states()
    n = len(states)
    settled = settle(damper(study.values), drives, np.tile(states, (len(frequencies), 1)),
                     np.repeat(np.arange(len(frequencies)), n),
                     SettleSettings(tolerance=study.tolerance, max_cycles=study.max_cycles), device=study.device)
    starts, attractors = settled.records()
    for k, record in enumerate(starts):
        f = frequencies[k // n]
        record.update(index=f * n + k % n, group=f)
    for record in attractors:
        record["group"] = frequencies[record["group"]]
    return {"index": number, "frequencies": frequencies, "starts": starts, "attractors": attractors,
            "cycles": settled.cycles, "seconds": time.perf_counter() - begin}


def open_fractions(model, spec: FractionSpec, folder: Path, resume: bool, force: bool):
    header = {**spec.to_dict(), "fmu_guid": model.guid}
    # the FMU's checks come after the chunks: a resumed study may ask for others
    same = tuple(k for k in header if k != "confirm")
    return open_folder(folder, HEADER_FILE, header, same, resume, force, "--out", "fractions study",
                       check=record_check(spec))


def record_check(spec: FractionSpec):
    """The check of a recorded chunk (:func:`piezo_fmu_harness.store.open_folder`): one of the
    study's chunks, its frequencies and the starts at each of them
    (:func:`piezo_fmu_harness.starts.chunks.check_chunk`), and the periods it marched."""
    layout = spec.chunks()

    def check(record: dict) -> None:
        within(record["index"], len(layout), "chunk")
        require(record, {"frequencies": list, "cycles": int})
        frequencies = layout[record["index"]]
        if record["frequencies"] != frequencies:
            raise Damaged(f"chunk {record['index']} is of the frequencies {record['frequencies']}, this study's of "
                          f"{frequencies}: a record of another run")
        check_chunk(record, [(f * spec.starts + k, f) for f in frequencies for k in range(spec.starts)])
    return check


def tasks(spec: FractionSpec) -> list:
    plain = spec.to_dict()
    return [(number, settle_chunk, (plain, number, frequencies)) for number, frequencies in enumerate(spec.chunks())]


def outcome(spec: FractionSpec, done: dict) -> tuple[list[dict], dict]:
    return merge([done[k] for k in sorted(done)], list(zip(spec.omegas.tolist(), spec.amplitudes)))


def checks(spec: FractionSpec, found: list[dict], starts: dict, backend, progress=None) -> list[dict]:
    """The FMU's checks (:func:`piezo_fmu_harness.starts.fmu_checks.confirm`): every attractor across
    the band (by its name) from one of its starts, and ``confirm`` random starts, each with the batch
    engine's sections of its start (its ``track``)."""
    from piezo_fmu.solver.batch import HarmonicHold, damper, tracks

    states = spec.states()
    names = track_names(found, list(range(len(spec.ratios))), spec.omegas.tolist())
    attractors = {f: [{**a, "id": k} for k, a in enumerate(found) if a["group"] == f] for f in range(len(spec.ratios))}

    def make(chosen: list[int]) -> list[dict]:
        payloads = []
        for f in sorted({starts[i]["group"] for i in chosen}):
            here = [i for i in chosen if starts[i]["group"] == f]
            periods = [starts[i]["periods"] for i in here]
            drive = HarmonicHold(float(spec.omegas[f]), spec.amplitudes[f], 0.0, spec.samples)
            paths = tracks(damper(spec.values), drive, states[[i % spec.starts for i in here]], [0] * len(here),
                           periods, spec.device)
            payloads += [{"index": i, "values": spec.values, "omega": float(spec.omegas[f]),
                          "amplitude": spec.amplitudes[f], "samples": spec.samples,
                          "start": states[i % spec.starts].tolist(), "periods": k, "track": path,
                          "cap": spec.max_cycles, "attractors": attractors[f], "study": starts[i]["attractor"]}
                         for i, k, path in zip(here, periods, paths)]
        return payloads
    return confirm(backend, starts, make, spec.confirm, spec.seed, key=lambda record: names[record["attractor"]],
                   what="fractions", progress=progress)


def build_dataset(spec: FractionSpec, found: list[dict], starts: dict, names: list[str]):
    from .transients import transient_variables

    return transient_variables(spec, starts, _shares_dataset(spec, found, starts, names))


def _shares_dataset(spec: FractionSpec, found: list[dict], starts: dict, names: list[str]):
    import xarray as xr

    order = sorted(set(names), key=lambda name: min(k for k, n in enumerate(names) if n == name))
    F, A = len(spec.ratios), len(order)
    fraction, low, high = np.zeros((F, A)), np.zeros((F, A)), np.zeros((F, A))
    amplitude, impacts = np.full((F, A), np.nan), np.full((F, A), np.nan)
    for f in range(F):
        for row in shares(found, starts, f):
            a = order.index(names[row["id"]])
            fraction[f, a], low[f, a], high[f, a] = row["share"], row["share_low"], row["share_high"]
            amplitude[f, a] = row.get("amplitude") if row.get("amplitude") is not None else np.nan
            impacts[f, a] = row.get("impacts_per_cycle") if row.get("impacts_per_cycle") is not None else np.nan
    dims = ("omega", "attractor")
    return xr.Dataset(
        {"fraction": (dims, fraction, {"units": "1", "long_name": "share of the starts that reach the attractor"}),
         "fraction_low": (dims, low, {"units": "1", "long_name": "95% Wilson interval, low"}),
         "fraction_high": (dims, high, {"units": "1", "long_name": "95% Wilson interval, high"}),
         "amplitude": (dims, amplitude, {"units": "m", "long_name": "amplitude of p on the attractor"}),
         "impacts_per_cycle": (dims, impacts, {"units": "1", "long_name": "impacts per forcing cycle"}),
         "attractor_name": (("attractor",), np.array(order, dtype=str), {})},
        coords={"omega": ("omega", spec.omegas, {"units": "rad/s", "long_name": "forcing frequency"}),
                "ratio": ("omega", np.array(spec.ratios), {"units": "1", "long_name": "w / sqrt(K/M)"})},
        attrs={"title": "piezo-impact damper: basin fractions across the band", "starts_per_frequency": spec.starts,
               "seed": spec.seed, "span_m": spec.span, "parameters": json.dumps(spec.values),
               "start": "p0 in [-S, S], p0' in [-S w_n, S w_n], impact mass at rest anywhere in the gap, base phase 0",
               "engine": "batch engine, checked through the FMU"})


def write(spec: FractionSpec, found: list[dict], starts: dict, checks: list[dict], folder: Path, times: dict,
          cycles: int, begin: float) -> dict:
    """Write the study's files (:data:`FILES`); ``times``: ``marching_s`` and ``checking_s``;
    ``begin``: when the command's work began (``time.perf_counter``), for ``wall_s``."""
    from ...datasets import csv_frame, save_dataset, units_of
    from .figure import draw
    from .transients import by_frequency, draw_transients

    names = track_names(found, list(range(len(spec.ratios))), spec.omegas.tolist())
    ds = build_dataset(spec, found, starts, names)
    save_dataset(ds, folder / "fractions.nc")
    frame = ds[["fraction", "fraction_low", "fraction_high", "amplitude", "impacts_per_cycle"]].to_dataframe()
    frame = frame.reset_index()
    frame["attractor"] = ds["attractor_name"].values[frame["attractor"].values]
    units = units_of(ds)
    csv_frame(frame[frame["fraction"] > 0], units).to_csv(folder / "fractions.csv", index=False)
    transients = by_frequency(ds)
    csv_frame(transients, units).to_csv(folder / "transients.csv", index=False)
    per_frequency = [{"ratio": r, "attractors": [{"name": names[row["id"]], "share": row["share"],
                                                  "share_low": row["share_low"], "share_high": row["share_high"],
                                                  "amplitude": row.get("amplitude"), "kind": row["kind"],
                                                  "motion": row.get("motion"), "exponent": row.get("exponent"),
                                                  "exponent_low": row.get("exponent_low"),
                                                  "exponent_high": row.get("exponent_high")}
                                                 for row in shares(found, starts, f)],
                       "transients": record}
                     for f, (r, record) in enumerate(zip(spec.ratios, transients.to_dict("records")))]
    undecided = [{"ratio": row["ratio"], "share": row["undecided"], "starts": row["undecided_starts"]}
                 for row in transients.to_dict("records") if row["undecided_starts"]]
    draw(ds, folder / "fractions.png")
    draw_transients(ds, folder / "transients.png")
    report = {"frequencies": len(spec.ratios), "starts_per_frequency": spec.starts,
              "wall_s": time.perf_counter() - begin, **times, "start_periods": cycles, "budget_periods": spec.max_cycles,
              "undecided": {"frequencies": len(undecided), "starts": sum(u["starts"] for u in undecided),
                            "where": undecided},
              "attractors": [str(n) for n in ds["attractor_name"].values],
              "by_frequency": per_frequency,
              "fmu_checks": {**tally(checks, times["checking_s"]),
                             "starts": [{**c, "study": names[c["study"]] if c["study"] is not None else None,
                                         "fmu": names[c["fmu"]] if c["fmu"] is not None else None} for c in checks]}}
    write_json(folder / "summary.json", report)
    return report
