"""Basins of attraction: which motion the machine reaches from where it starts,
at one frequency.

A grid of initial states ``p0`` against ``p0'``, the impact mass at rest in the middle of the gap
(``q0 = p0``, ``q0' = 0``), the base starting at phase 0. Every start is marched on the batch
engine (``piezo_fmu.solver.batch``) to the motion its own trajectory reaches (the rule of
``piezo_fmu.solver.batch.attractors.settle``): a stable orbit it is seen converging to, with its impact
sequence, the motion without impacts once it provably never reaches a barrier again, or, after
the budget of ``--max-cycles`` periods, **undecided** (a cap is a budget, not a
verdict), unless the map's survival curve shows that what is left persists and the start's own
exponent says chaotic or quasi-periodic (:func:`piezo_fmu_harness.starts.attractors.merge`). The
periods each start took are the transient's length, mapped beside the basins. The grid is split into chunks
(:mod:`piezo_fmu_harness.starts.chunks`), each a task of the sweep engine, appended to
``points.jsonl`` as it finishes (``--resume`` runs the others).

**The FMU checks the answer.** For every attractor the start that reached it soonest, and a seeded
random sample of ``--confirm`` starts, are marched through the FMU, which must reach the attractor
the map gives them (:mod:`piezo_fmu_harness.starts.destination`); ``summary.json`` lists each check.

Files: ``basins.nc`` (``basin``: the attractor each start reaches, on ``p0 x dp0``, a label of
the coordinate ``attractor``; the periods it took; the attractors with their shares and 95%
intervals, over ``attractor``), ``basins.csv`` (a row a start), ``summary.json`` (the budget, the
shares, what stayed undecided, the survival fit: the mean transient lifetime with its interval and
the plateau, the boundary's uncertainty, the checks, the times of the marching and of the checks),
``basins.png`` (the map and the transient's length); ``basins.json`` and ``points.jsonl``.

This study reads the simulation core's batch engine (``piezo_fmu.solver.batch``) besides the FMU,
which checks it: the one exception, with the fractions and the bifurcation diagram, to the
harness's rule that it reads nothing but the FMU.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ...starts.attractors import boundary, merge, shares
from ...starts.chunks import check_chunk, chunks
from ...starts.fmu_checks import tally
from ...starts.transients import counts, escape
from ...store import open_folder, within, write_json
from ...wording import per_cycle

HEADER_FILE = "basins.json"
#: The files a basin map writes besides its header and ``points.jsonl``.
FILES = ("basins.nc", "basins.csv", "summary.json", "basins.png")
#: The default grid: ``p0`` and ``p0'/w`` each from -2 to 2 times the main mass's linear amplitude,
#: 101 x 101 starts.
DEFAULT_SPAN, DEFAULT_COUNT = 2.0, 101
#: The budget of periods a start (the batch engine's ``SettleSettings.max_cycles``).
DEFAULT_MAX_CYCLES = 6000
#: FMU checks beyond one per attractor.
DEFAULT_CONFIRM = 10


@dataclass(frozen=True)
class BasinSpec:
    """One basin map (SI)."""

    ratio: float
    omega: float
    amplitude: float
    values: dict
    p0: tuple       # (lo, hi, count), m
    dp0: tuple      # (lo, hi, count), m/s
    samples: int = 64
    tolerance: float = 1e-6
    max_cycles: int = DEFAULT_MAX_CYCLES
    device: str = "cpu"
    confirm: int = DEFAULT_CONFIRM
    seed: int = 0

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.p0[2]), int(self.dp0[2])

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        return np.linspace(*self.p0[:2], self.shape[0]), np.linspace(*self.dp0[:2], self.shape[1])

    def starts(self) -> np.ndarray:
        """``(p0, p0', q0, q0')`` of every start, row-major over ``p0 x dp0``."""
        p0, dp0 = np.meshgrid(*self.axes(), indexing="ij")
        p0, dp0 = p0.ravel(), dp0.ravel()
        return np.stack([p0, dp0, p0, np.zeros_like(p0)], axis=1)

    def to_dict(self) -> dict:
        return asdict(self)


def settle_chunk(instance, spec: dict, number: int, indices: list[int]) -> dict:
    """A task: march the starts ``indices`` of the map to where they go, on the batch engine."""
    from piezo_fmu.solver.batch import HarmonicHold, SettleSettings, damper, settle

    begin = time.perf_counter()
    basin = BasinSpec(**{**spec, "p0": tuple(spec["p0"]), "dp0": tuple(spec["dp0"])})
    drive = HarmonicHold(basin.omega, basin.amplitude, 0.0, basin.samples)
    settled = settle(damper(basin.values), drive, basin.starts()[indices],
                     settings=SettleSettings(tolerance=basin.tolerance, max_cycles=basin.max_cycles),
                     device=basin.device)
    starts, attractors = settled.records()
    for index, record in zip(indices, starts):
        record.update(index=index, group=0)
    return {"index": number, "starts": starts, "attractors": attractors, "cycles": settled.cycles,
            "seconds": time.perf_counter() - begin}


def open_basins(model, spec: BasinSpec, folder: Path, resume: bool, force: bool):
    header = {**spec.to_dict(), "fmu_guid": model.guid}
    # the FMU's checks come after the chunks: a resumed map may ask for others
    same = tuple(k for k in header if k not in ("confirm", "seed"))
    return open_folder(folder, HEADER_FILE, header, same, resume, force, "--out", "basin map",
                       check=record_check(spec))


def record_check(spec: BasinSpec):
    """The check of a recorded chunk (:func:`piezo_fmu_harness.store.open_folder`): one of the
    map's chunks, with its starts (:func:`piezo_fmu_harness.starts.chunks.check_chunk`)."""
    layout = chunks(spec.shape[0] * spec.shape[1])

    def check(record: dict) -> None:
        within(record["index"], len(layout), "chunk")
        check_chunk(record, [(index, 0) for index in layout[record["index"]]])
    return check


def tasks(spec: BasinSpec) -> list:
    plain = spec.to_dict()
    return [(number, settle_chunk, (plain, number, indices))
            for number, indices in enumerate(chunks(spec.shape[0] * spec.shape[1]))]


def outcome(spec: BasinSpec, done: dict) -> tuple[list[dict], dict]:
    """The attractors and each start's record, from the chunks in ``done``."""
    return merge([done[k] for k in sorted(done)], [(spec.omega, spec.amplitude)])


def payloads(spec: BasinSpec, found: list[dict], starts: dict):
    """The maker of the FMU checks' payloads (:func:`piezo_fmu_harness.starts.fmu_checks.confirm`), each
    with the batch engine's sections of its start (its ``track``)."""
    grid = spec.starts()
    attractors = [{**a, "id": k} for k, a in enumerate(found)]

    def make(chosen: list[int]) -> list[dict]:
        from piezo_fmu.solver.batch import HarmonicHold, damper, tracks

        periods = [starts[i]["periods"] for i in chosen]
        paths = tracks(damper(spec.values), HarmonicHold(spec.omega, spec.amplitude, 0.0, spec.samples),
                       grid[chosen], [0] * len(chosen), periods, spec.device)
        return [{"index": i, "values": spec.values, "omega": spec.omega, "amplitude": spec.amplitude,
                 "samples": spec.samples, "start": grid[i].tolist(), "periods": k, "track": path,
                 "cap": spec.max_cycles,
                 "attractors": attractors, "study": starts[i]["attractor"]}
                for i, k, path in zip(chosen, periods, paths)]
    return make


def write(spec: BasinSpec, found: list[dict], starts: dict, checks: list[dict], folder: Path, times: dict,
          begin: float) -> dict:
    """Write the map's files (:data:`FILES`); ``times``: ``marching_s`` and ``checking_s``;
    ``begin``: when the command's work began (``time.perf_counter``), for ``wall_s``."""
    import xarray as xr

    from ...datasets import csv_frame, save_dataset, units_of
    from .figure import draw

    shape = spec.shape
    count = shape[0] * shape[1]
    labels = np.array([starts[i]["attractor"] for i in range(count)]).reshape(shape)
    periods = np.array([starts[i]["periods"] for i in range(count)]).reshape(shape)
    rows = shares(found, starts, 0)
    order = [row["id"] for row in rows]  # attractors by decreasing share
    relabel = {old: new for new, old in enumerate(order)}
    names = _distinct([_name(row) for row in rows])
    p0, dp0 = spec.axes()
    numbers = {name: np.array([row.get(name) if row.get(name) is not None else np.nan for row in rows], float)
               for name in ("share", "share_low", "share_high", "amplitude", "impacts_per_cycle", "max_multiplier")}
    ds = xr.Dataset(
        {"basin": (("p0", "dp0"), np.vectorize(relabel.get)(labels),
                   {"long_name": "the attractor each start reaches: its label on the coordinate attractor"}),
         "periods": (("p0", "dp0"), periods, {"units": "1", "long_name": "forcing periods marched until the motion "
                                                                         "was known"}),
         "attractor_name": (("attractor",), np.array(names, dtype=str), {}),
         "attractor_share": (("attractor",), numbers["share"], {"units": "1", "long_name": "share of the starts"}),
         "share_low": (("attractor",), numbers["share_low"], {"units": "1", "long_name": "95% Wilson interval, low"}),
         "share_high": (("attractor",), numbers["share_high"], {"units": "1", "long_name": "95% Wilson interval, high"}),
         "attractor_amplitude": (("attractor",), numbers["amplitude"], {"units": "m", "long_name": "amplitude of p"}),
         "impacts_per_cycle": (("attractor",), numbers["impacts_per_cycle"], {"units": "1"}),
         "max_multiplier": (("attractor",), numbers["max_multiplier"],
                            {"units": "1", "long_name": "largest Floquet multiplier (the neutral pair left out)"})},
        coords={"p0": ("p0", p0, {"units": "m", "long_name": "initial displacement of the main mass"}),
                "dp0": ("dp0", dp0, {"units": "m/s", "long_name": "initial velocity of the main mass"}),
                "attractor": ("attractor", np.arange(len(rows)), {"long_name": "attractor, by decreasing share"})},
        attrs={"title": "piezo-impact damper: basins of attraction", "ratio": spec.ratio, "omega_rad_per_s": spec.omega,
               "budget_periods": spec.max_cycles,
               "base_amplitude_m": spec.amplitude, "start": "q0 = p0, q0' = 0, base phase 0",
               "parameters": json.dumps(spec.values), "engine": "batch engine, checked through the FMU"})
    save_dataset(ds, folder / "basins.nc")
    frame = ds.drop_dims("attractor").to_dataframe().reset_index().rename(columns={"basin": "attractor"})
    frame["attractor_name"] = np.array(names)[frame["attractor"].values]
    csv_frame(frame, units_of(ds)).to_csv(folder / "basins.csv", index=False)
    records = list(starts.values())
    fit = escape([min(r["periods"], spec.max_cycles) for r in records if r["label"] != -2],
                 [r["label"] >= 0 for r in records if r["label"] != -2], spec.max_cycles)
    undecided = sum(1 for r in records if str(r.get("motion", "")).startswith("undecided"))
    draw(ds, folder / "basins.png")
    report = {"ratio": spec.ratio, "starts": count, "grid": list(shape), "wall_s": time.perf_counter() - begin,
              **times, "budget_periods": spec.max_cycles,
              "undecided": {"starts": undecided, "share": undecided / count},
              "transients": counts(fit),
              "attractors": [_summary_row(row, name, relabel) for row, name in zip(rows, names)],
              "boundary": boundary(ds["basin"].values),
              "fmu_checks": {**tally(checks, times["checking_s"]),
                             "starts": [{**c, "study": relabel.get(c["study"]), "fmu": relabel.get(c["fmu"])}
                                        for c in checks]}}
    write_json(folder / "summary.json", report)
    return report


def _summary_row(row: dict, name: str, relabel: dict) -> dict:
    keep = ("kind", "motion", "order", "impacts", "impacts_per_cycle", "amplitude", "max_multiplier", "starts",
            "share", "share_low", "share_high", "sections", "sides", "exponent", "exponent_low", "exponent_high")
    return {"id": relabel[row["id"]], "name": name, **{k: row[k] for k in keep if k in row}}


def _distinct(names: list[str]) -> list[str]:
    """``names`` with a repeat told apart by ``#2``, ``#3``, ... (an orbit and its mirror image)."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name} #{seen[name]}")
    return out


def _name(attractor: dict) -> str:
    if attractor["kind"] == "orbit":
        return (f"order {attractor['order']}, {per_cycle(attractor['impacts_per_cycle'])}, "
                f"{1e3 * attractor['amplitude']:.2f} mm")
    if attractor["kind"] == "no impacts":
        return f"no impacts, {1e3 * attractor['amplitude']:.2f} mm"
    if attractor["kind"] == "set aside":
        return "set aside by the batch engine"
    if attractor["kind"] == "undecided":
        return f"{attractor['motion']} within the budget"
    return f"{attractor['motion']} (persists)"
