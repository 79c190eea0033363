"""``piezo-fmu continuation``: the branches of periodic orbits of the forced response,
followed through their folds, with their stability and bifurcations.

1. **Seeds.** A sweep up and a sweep down over ``--count`` values of the parameter (the frequency
   response's shooting, :func:`piezo_fmu_harness.periodic.band.solve_point`, with the damper)
   gives the orbits with impacts it meets: the stable ones it reports and the unstable ones it set
   aside. Orbits without an impact are not continued: they are the linear response in closed form,
   and the free impact mass makes them a family, not a branch.
2. **Branches.** Each seed not already on a branch is followed both ways
   (:func:`piezo_fmu_harness.studies.continuation.branches.trace_branch`, a task of the sweep engine, so two run at a
   time), and the seeds of the period-doubled branches it finds are followed in turn.
3. **Results.** ``continuation.nc`` (the points of every branch on a ``point`` dimension, their
   multipliers, and the bifurcations on an ``event`` dimension), ``branches.csv``, ``events.csv``,
   ``summary.json`` and ``continuation.png``: stable branches solid, unstable dashed, over the
   sweeps' points, the bifurcations marked.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ...periodic.band import solve_chain
from ...periodic.steady_state import Settings as SteadySettings
from ...store import jsonable, write_json
from .branches import distance_to_branch, trace_branch
from .tracer import Problem, Settings

#: A seed lies on a branch when the branch's amplitude at its parameter is within this (relative).
COVERED = 2e-3


def seed_chain(instance, problem: dict, steady: dict, lams: list, direction: str) -> dict:
    """One sweep of the seeds (a task): the frequency response's shooting at each value of
    ``lams`` in order, each from the previous state, with the parameter value on each record."""
    problem = Problem(**problem)
    points = []
    for lam in lams:
        omega, amplitude, values = problem.omega_and_amplitude(lam)
        points.append((values, omega, amplitude))
    records = solve_chain(instance, points, SteadySettings(**steady))
    for lam, record in zip(lams, records):
        record.update(lam=lam, direction=direction)
    return {"direction": direction, "records": records}


def seeds_of(chains: list[dict]) -> list[dict]:
    """The orbits with impacts the sweeps met, stable ones first, then by parameter value."""
    seeds = []
    for chain in chains:
        for record in chain["records"]:
            orbits = ([record] if record.get("settled") else []) + list(record.get("unstable_orbits") or ())
            for orbit in orbits:
                if (orbit.get("impacts_per_cycle") or 0) > 0 and orbit.get("verdict") in ("stable", "unstable"):
                    seeds.append({"lam": record["lam"], "state": orbit["state"], "phase": orbit["phase"],
                                  "order": orbit["order"], "amplitude": orbit["amplitude"], "depth": 0,
                                  "impacts_per_cycle": orbit["impacts_per_cycle"],
                                  "stable": orbit["verdict"] == "stable", "direction": chain["direction"]})
    return sorted(seeds, key=lambda s: (not s["stable"], s["lam"]))


class Continuation:
    """Seeds, then branches, on one backend (see the module's text)."""

    def __init__(self, problem: Problem, settings: Settings, steady: SteadySettings, lams: list,
                 max_branches: int):
        self.problem, self.settings, self.steady, self.lams = problem, settings, steady, lams
        self.max_branches = max_branches
        self.chains: list[dict] = []
        self.branches: list[dict] = []
        self.pending: list[dict] = []
        self.skipped = 0
        self.seconds: dict = {}

    def run(self, backend, recorded: tuple = (), log=None, progress=None) -> None:
        """Seeds, then branches, on ``backend``, with a progress bar on stderr unless ``progress`` is
        False. ``recorded``: the records of the tasks an earlier run of this study finished, in the
        order they finished (:mod:`.journal`): they are replayed, not run again; ``log(record)``
        keeps the record of each task as it finishes."""
        import copy
        import sys

        from tqdm import tqdm

        from ...spec import UsageError

        log = log or (lambda record: None)
        chains = {record["direction"]: record for record in recorded if record["index"] < 2}
        branches = [record for record in recorded if record["index"] >= 2]
        bar = tqdm(total=2, initial=len(chains), unit="task", desc="continuation", dynamic_ncols=True,
                   disable=(not progress) if progress is not None else None, file=sys.stderr)
        try:
            begin = time.perf_counter()
            args = (asdict(self.problem), asdict(self.steady))
            tasks = [(direction, seed_chain, (*args, lams, direction))
                     for direction, lams in (("up", self.lams), ("down", self.lams[::-1])) if direction not in chains]
            for direction, result in backend.run_tasks(tasks):
                chains[direction] = {"index": ("up", "down").index(direction), **result}
                log(jsonable(chains[direction]))
                bar.update(1)
            self.chains = [chains["up"], chains["down"]]
            self.seconds["seeds"] = time.perf_counter() - begin
            begin = time.perf_counter()
            self.pending, self.running = seeds_of(self.chains), {}
            given = [task for task in (self._task(), self._task()) if task]
            for record in branches:
                if record["index"] - 1 not in self.running:
                    raise UsageError(f"--resume: branch task {record['index'] - 1} of the record is not one this "
                                     "study gives out at that point: a record of another run; nothing was changed; "
                                     "use --force to start over (it discards the recorded points)")
                given += self._follow(record["index"] - 1, copy.deepcopy(record["branch"]))
            bar.total += len(given)
            bar.update(len(branches))

            def follow(tag, branch: dict) -> list:
                log({"index": 1 + tag, "branch": jsonable(branch)})
                more = self._follow(tag, branch)
                bar.total += len(more)
                return more

            for _ in backend.run_tasks([task for task in given if task[0] in self.running], follow):
                bar.update(1)
            self.seconds["branches"] = time.perf_counter() - begin
        finally:
            bar.close()

    def _task(self):
        """The next seed to follow: not on a branch already followed, and not of the kind (order,
        impacts per cycle) of a branch still running, which is likely to cover it."""
        if len(self.branches) + len(self.running) >= self.max_branches:
            return None
        for seed in list(self.pending):
            if self._covered(seed):
                self.pending.remove(seed)
                self.skipped += 1
                continue
            if _kind(seed) in self.running.values() and seed.get("depth", 0) == 0:
                continue
            self.pending.remove(seed)
            self._tags += 1
            self.running[self._tags] = _kind(seed)
            return (self._tags, trace_branch, (asdict(self.problem), asdict(self.settings), seed))
        return None

    running: dict
    _tags = 0

    def _follow(self, tag, branch: dict) -> list:
        self.running.pop(tag, None)
        branch["index"] = len(self.branches)
        for event in branch["events"]:
            event["branch"] = branch["index"]
        self.branches.append(branch)
        self.pending = list(branch["seeds"]) + self.pending
        tasks = []
        while len(self.running) < 2 and (task := self._task()) is not None:
            tasks.append(task)
        return tasks

    def _covered(self, seed: dict) -> bool:
        if seed.get("depth", 0) > 0:
            return False
        return any(distance_to_branch(branch["points"], seed["lam"], seed["amplitude"], seed["order"]) < COVERED
                   for branch in self.branches)

    def events(self) -> list[dict]:
        return [event for branch in self.branches for event in branch["events"]]

    def evaluations(self) -> int:
        return sum(branch["evaluations"] for branch in self.branches)


def _kind(seed: dict) -> tuple:
    return seed["order"], round(seed.get("impacts_per_cycle", 0), 6)


# -- results -------------------------------------------------------------------------------------

POINT_FIELDS = {
    "lam": ("", "the continued parameter"),
    "omega": ("rad/s", "forcing frequency"),
    "base_amplitude": ("m", "base displacement amplitude Y"),
    "amplitude": ("m", "amplitude of the main mass, half its peak-to-peak over the orbit"),
    "impacts_per_cycle": ("1", "impacts per forcing cycle"),
    "order": ("1", "period of the orbit in forcing periods"),
    "max_multiplier": ("1", "largest modulus of the Floquet multipliers (< 1: stable)"),
    "min_impact_velocity": ("m/s", "smallest relative velocity at an impact of the orbit (grazing as it goes to 0)"),
    "phase": ("rad", "forcing phase of the section"),
}


def build_dataset(study: Continuation, parameter_units: str):
    import xarray as xr

    rows = [(branch["index"], point) for branch in study.branches for point in branch["points"]]
    variables = {"branch": (("point",), np.array([b for b, _ in rows], dtype=int),
                            {"long_name": "the branch the point belongs to"})}
    for key, (units, text) in POINT_FIELDS.items():
        values = [np.nan if p.get(key) is None else float(p[key]) for _, p in rows]
        variables[key] = (("point",), np.array(values, dtype=float),
                          {"units": parameter_units if key == "lam" else units, "long_name": text})
    variables["stable"] = (("point",), np.array([int(p["stable"]) for _, p in rows], dtype=np.int8),
                           {"units": "1", "long_name": "1: every multiplier inside the unit circle"})
    multipliers = np.array([[complex(*m) for m in p["multipliers"]] for _, p in rows]).reshape(len(rows), 4)
    for part, values in (("real", multipliers.real), ("imag", multipliers.imag)):
        variables[f"multiplier_{part}"] = (("point", "multiplier"), values,
                                           {"units": "1", "long_name": f"{part} part of the Floquet multipliers"})
    variables["state"] = (("point", "coordinate"), np.array([p["state"] for _, p in rows]).reshape(len(rows), 4),
                          {"long_name": "(p, p', q, q') at the section (m, m/s)"})
    events = study.events()
    variables["event_kind"] = (("event",), np.array([e["kind"] for e in events], dtype=str),
                               {"long_name": "fold, period doubling, Neimark-Sacker, branch point or grazing"})
    variables["event_branch"] = (("event",), np.array([e["branch"] for e in events], dtype=int), {})
    variables["event_lam"] = (("event",), np.array([e["lam"] for e in events], dtype=float),
                              {"units": parameter_units, "long_name": "where it happens"})
    variables["event_amplitude"] = (("event",), np.array([e["amplitude"] for e in events], dtype=float),
                                    {"units": "m", "long_name": "the branch's amplitude there"})
    crossing = np.array([complex(*e["multiplier"]) if e["multiplier"] else complex(np.nan, np.nan) for e in events])
    variables["event_multiplier_real"] = (("event",), crossing.real,
                                          {"units": "1", "long_name": "the multiplier of the crossing, real part"})
    variables["event_multiplier_imag"] = (("event",), crossing.imag, {"units": "1"})
    for flag, text in (("crosses_plus_one", "a real multiplier crosses +1 between the two points"),
                       ("crosses_minus_one", "a real multiplier crosses -1 between the two points")):
        variables[f"event_{flag}"] = (("event",), np.array([int(e.get(flag, False)) for e in events], dtype=np.int8),
                                      {"units": "1", "long_name": text})
    variables["event_stability_changes"] = (("event",), np.array([int(e["stable_before"] != e["stable_after"])
                                                                  for e in events], dtype=np.int8),
                                            {"units": "1", "long_name": "1: stable on one side, unstable on the other"})
    variables["event_from"] = (("event",), np.array([e["ratio_between"][0] if "ratio_between" in e else e["lam"]
                                                     for e in events], dtype=float),
                               {"units": parameter_units, "long_name": "the parameter at the point before"})
    variables["event_to"] = (("event",), np.array([e["ratio_between"][1] if "ratio_between" in e else e["lam"]
                                                   for e in events], dtype=float),
                             {"units": parameter_units, "long_name": "the parameter at the point after"})
    attrs = {"title": "piezo-impact damper: branches of periodic orbits (pseudo-arclength continuation)",
             "parameter": study.problem.parameter, "problem": json.dumps(asdict(study.problem)),
             "settings": json.dumps(asdict(study.settings))}
    return xr.Dataset(variables, coords={"coordinate": ["p", "dp", "q", "dq"]}, attrs=attrs)


def summarize(study: Continuation) -> dict:
    events = study.events()
    return {"parameter": study.problem.parameter, "branches": len(study.branches),
            "points": sum(len(b["points"]) for b in study.branches), "evaluations": study.evaluations(),
            "seeds_skipped_on_a_branch": study.skipped, "seconds": study.seconds,
            "events": {kind: sorted(round(e["lam"], 6) for e in events if e["kind"] == kind)
                       for kind in sorted({e["kind"] for e in events})},
            "ends": [b["ends"] for b in study.branches]}


#: The files a continuation writes besides its header and ``points.jsonl`` (:mod:`.journal`).
FILES = ("continuation.nc", "branches.csv", "events.csv", "summary.json", "sweeps.jsonl", "continuation.png")


def write(study: Continuation, folder: Path, parameter_units: str) -> list[Path]:
    from ...datasets import csv_frame, save_dataset, units_of
    from . import figure as continuation_figure

    ds = build_dataset(study, parameter_units)
    files = [folder / "continuation.nc", folder / "branches.csv", folder / "events.csv", folder / "summary.json",
             folder / "sweeps.jsonl"]
    save_dataset(ds, files[0])
    units = units_of(ds)
    # a row a point, a row a bifurcation (the multipliers and the state stay in the NetCDF)
    csv_frame(ds.drop_dims(["event", "coordinate", "multiplier"]).to_dataframe().reset_index(), units).to_csv(
        files[1], index=False)
    csv_frame(ds.drop_dims(["point", "coordinate", "multiplier"]).to_dataframe().reset_index(), units).to_csv(
        files[2], index=False)
    write_json(files[3], summarize(study))
    with open(files[4], "w") as out:
        for chain in study.chains:
            for record in chain["records"]:
                out.write(json.dumps(record) + "\n")
    files.append(continuation_figure.draw(ds, study.chains, folder / "continuation.png"))
    return files


# -- the command ---------------------------------------------------------------------------------

#: The seed sweep's defaults: 16 values over the frequency response's band (a step of 0.1).
SEED_DEFAULTS = {"ratios": (0.5, 2.0), "count": 16, "max_cycles": 400, "fewest": 2}
MAX_BRANCHES = 12


def parameter_range(model, args, spec) -> tuple[str, tuple, list, str]:
    """The continued parameter, its range, the seeds' values and its units, checked."""
    from ...checks import whole
    from ...spec import UsageError

    name = args.parameter
    if name == "ratio":
        if args.range:
            raise UsageError("--range: the frequency ratio's range is --ratio-min and --ratio-max")
        return name, (spec.ratios[0], spec.ratios[-1]), list(spec.ratios), "1"
    if name != "Y" and (name not in model.parameters or model.parameters[name].type != "Real"
                        or name in ("p0", "dp0", "q0", "dq0", "R_load")):
        raise UsageError(f"--parameter {name}: not a parameter that can be continued (ratio, Y, or a Real parameter "
                         "of the FMU other than the initial state and R_load)")
    if not args.range:
        raise UsageError(f"--parameter {name} needs --range LO:HI")
    try:
        lo, hi = (float(v) for v in args.range.split(":"))
    except ValueError:
        raise UsageError(f"--range {args.range}: give LO:HI, two numbers") from None
    if not lo < hi:
        raise UsageError(f"--range {args.range}: {'reversed' if lo > hi else 'empty'} range (give LO < HI)")
    for value in (lo, hi):
        if name == "Y":
            if not value > 0:
                raise UsageError(f"--range {args.range}: Y = {value:g} m is outside the allowed range (0, inf) m")
        else:
            try:
                model.parameters[name].coerce(value)
            except ValueError as error:
                raise UsageError(f"--range {args.range}: {error}") from None
    count = whole(len(spec.ratios), "--count", 2, "need at least 2 seed values")
    units = "m" if name == "Y" else (model.parameters[name].unit or "1")
    return name, (lo, hi), [float(v) for v in np.linspace(lo, hi, count)], units


def command(args) -> int:
    import signal
    import sys

    from ...fmu import discard

    from ...checks import PROG, interrupt, make_backend, open_model, positive, preflight, whole, worker_count
    from ...engine import InProcess
    from ...periodic.band import frequency_spec
    from ...store import PointStore
    from ...wording import counted
    from . import journal

    model = open_model(args)
    jobs = worker_count(args)
    unzipdir, instance = preflight(model, [{}], "--fmu")
    try:
        spec = frequency_spec(args, model, instance, SEED_DEFAULTS)
        parameter, bounds, lams, units = parameter_range(model, args, spec)
        ratio = positive(args.ratio, "--ratio", "the frequency ratio w / w_n held fixed", "")
        settings = Settings(max_points=whole(args.max_points, "--max-points", 10,
                                             "need at least 10 points a direction"))
        branches = whole(args.max_branches, "--max-branches", 1, "need at least one branch")
        problem = Problem(values=spec.values, parameter=parameter, bounds=bounds, natural=spec.natural, ratio=ratio,
                          amplitude=spec.amplitude, acceleration=spec.acceleration, samples=spec.settings.samples,
                          tolerance=spec.settings.tolerance)
        study = Continuation(problem, settings, spec.settings, lams, branches)
        folder, done, start_over = journal.open_continuation(model, study, args.out, args.resume, args.force)
        backend = (InProcess(instance) if jobs == 1 and not (args.scheduler or args.dask_local)
                   else make_backend(args, model, unzipdir, min(jobs, 2)))
        if start_over:
            PointStore(folder).clear()
        (folder / journal.HEADER_FILE).write_text(json.dumps({**journal.header(study), "fmu_guid": model.guid},
                                                             indent=2) + "\n")
        previous = signal.signal(signal.SIGTERM, interrupt)
        interrupted = True
        try:
            with PointStore(folder) as store:
                study.run(backend, tuple(done.values()), store.append, False if args.no_progress else None)
            interrupted = False
        except KeyboardInterrupt:
            print(f"\n{PROG} continuation: interrupted; {counted(len(study.branches), 'branch')} and the seeds' sweeps "
                  f"are saved in {folder / 'points.jsonl'}; run the same command with --resume to finish",
                  file=sys.stderr)
            return 130
        finally:
            signal.signal(signal.SIGTERM, previous)
            backend.close(cancel=interrupted)
    finally:
        instance.free()
        discard(unzipdir)
    write(study, folder, units)
    report = summarize(study)
    print(f"{PROG} continuation in {parameter}: {counted(report['branches'], 'branch')}, "
          f"{counted(report['points'], 'point')}, {counted(report['evaluations'], 'run')} of the period map "
          f"({report['seconds']['seeds']:.1f} s of seeds, {report['seconds']['branches']:.1f} s of branches)")
    for kind, where in report["events"].items():
        print(f"  {kind}: {len(where)} at {', '.join(f'{v:.4g}' for v in where)}")
    print(f"  results in {folder}")
    return 0
