"""``--resume`` on a damaged results folder: every study that resumes (sweep, load-sweep,
frequency-response, continuation, bifurcation, optimize, basins, fractions), each run once at its
smallest, then resumed from a copy of its folder with one line spoiled. A line that is not JSON, a record without the study's
fields, or a record of another run stops the run with exit status 2 and one line naming the file,
the line and ``--force``, and the folder is left byte for byte as it was; a half-written last line
(a killed writer's) is still cut off and its point recomputed. A header that cannot be read, or
points without a header, are refused the same way; an empty folder resumes as a fresh run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from fmu_host import run_cli

ROOT = Path(__file__).resolve().parent.parent
FMU = ROOT / "fmus" / "PiezoImpactDamper.fmu"
#: Each study at its smallest, and the file its records go to.
STUDIES = {
    "sweep": (("--grid", "x1=0:0.03:2", "--stop-time", 0.2), "points.jsonl"),
    "load-sweep": (("--r-min", 1e5, "--r-max", 1e7, "--count", 3, "--models", 1, "--stop-time", 0.2, "--no-impact"),
                   "points.jsonl"),
    "continuation": (("--set", "d=1", "--ratio-min", 1.9, "--ratio-max", 2.0, "--count", 2), "points.jsonl"),
    "bifurcation": (("--ratio-min", 1.1, "--ratio-max", 1.2, "--count", 2, "--max-cycles", 40, "--confirm", 0),
                    "points.jsonl"),
    "frequency-response": (("--set", "d=1", "--ratio-min", 0.9, "--ratio-max", 1.0, "--count", 2), "points.jsonl"),
    "optimize": (("--param", "m=0.02:0.2", "--maxiter", 1, "--popsize", 2, "--no-grid", "--stop-time", 0.5),
                 "evaluations.jsonl"),
    "basins": (("--ratio", 1.2, "--grid", 2, "--confirm", 0), "points.jsonl"),
    "fractions": (("--ratio-min", 1.15, "--ratio-max", 1.2, "--count", 2, "--starts", 2, "--max-cycles", 100,
                   "--confirm", 0), "points.jsonl"),
    "random": (("--realizations", 60, "--duration", 2, "--warmup", 0.5, "--confirm", 0), "points.jsonl"),
}
COMMON = ("--jobs", 1, "--no-progress", "--fmu", FMU)


def other_run(record: dict, study: str) -> dict:
    """``record``, the first of the finished run, as another run of the study could have written it."""
    if study == "optimize":
        return record  # numbered 0 again, where the log's numbers only increase
    return {**record, "index": 99}  # a point or chunk beyond this run's


@pytest.fixture(scope="module", params=list(STUDIES))
def finished(request, tmp_path_factory) -> tuple[str, Path]:
    """A study run to its end in a folder of its own."""
    out = tmp_path_factory.mktemp(request.param)
    assert run_cli(request.param, *STUDIES[request.param][0], *COMMON, "--out", out) == 0
    return request.param, out


def resume(study: str, folder: Path) -> int:
    return run_cli(study, *STUDIES[study][0], *COMMON, "--out", folder, "--resume")


def snapshot(folder: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir())}


def spoiled(finished, tmp_path, line: str) -> tuple[str, Path, int]:
    """A copy of the finished folder with ``line`` before its last record; returns the study, the
    points file and the spoiled line's number."""
    study, folder = finished
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    points = copy / STUDIES[study][1]
    lines = points.read_text().splitlines(keepends=True)
    points.write_text("".join(lines[:-1] + [line + "\n", lines[-1]]))
    return study, points, len(lines)


def assert_refused_unchanged(capsys, recwarn, study: str, points: Path, number: int, words: tuple) -> None:
    """The resume exits with status 2 and one line that names the file, the line and ``--force``
    (no traceback, no warning), and changes no file of the folder."""
    before = snapshot(points.parent)
    capsys.readouterr()
    assert resume(study, points.parent) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"piezo-fmu {study}: error: {points}: line {number}: "), err
    assert "use --force to start over (it discards the recorded points)" in err
    for word in words:
        assert word in err, (word, err)
    assert not [str(w.message) for w in recwarn]
    assert snapshot(points.parent) == before


def test_a_line_that_is_not_json_stops_the_resume_and_changes_nothing(finished, tmp_path, capsys, recwarn):
    study, points, number = spoiled(finished, tmp_path, "garbage")
    assert_refused_unchanged(capsys, recwarn, study, points, number, ("not JSON",))


def test_garbage_appended_after_the_last_record_stops_the_resume_and_changes_nothing(finished, tmp_path, capsys,
                                                                                     recwarn):
    study, folder = finished
    shutil.copytree(folder, tmp_path / "copy")
    points = tmp_path / "copy" / STUDIES[study][1]
    count = len(points.read_text().splitlines())
    with open(points, "a") as handle:
        handle.write("garbage\n")  # a complete line: not a killed writer's
    assert_refused_unchanged(capsys, recwarn, study, points, count + 1, ("not JSON",))


@pytest.mark.parametrize("line, words", [('{"index": 0}', ("is missing",)), ("[1, 2]", ("not a record",)),
                                         ('{"index": "0"}', ("'index' is \"0\", not a whole number",))])
def test_a_record_of_the_wrong_shape_stops_the_resume_and_changes_nothing(finished, tmp_path, capsys, recwarn, line,
                                                                          words):
    study, points, number = spoiled(finished, tmp_path, line)
    assert_refused_unchanged(capsys, recwarn, study, points, number, words)


def test_a_record_of_another_run_stops_the_resume_and_changes_nothing(finished, tmp_path, capsys, recwarn):
    study, folder = finished
    first = json.loads((folder / STUDIES[study][1]).read_text().splitlines()[0])
    study, points, number = spoiled(finished, tmp_path, json.dumps(other_run(first, study)))
    assert_refused_unchanged(capsys, recwarn, study, points, number, ("a record of another run",))


def test_a_half_written_last_line_is_cut_and_its_record_computed_again(finished, tmp_path):
    study, folder = finished
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    points = copy / STUDIES[study][1]
    lines = points.read_text().splitlines(keepends=True)
    points.write_text("".join(lines[:-1]) + lines[-1][:len(lines[-1]) // 2])  # killed while writing it
    assert resume(study, copy) == 0
    after = points.read_text().splitlines(keepends=True)
    assert after[:-1] == lines[:-1]  # the finished records, untouched
    assert len(after) == len(lines) and after[-1].endswith("\n")
    assert json.loads(after[-1])["index"] == json.loads(lines[-1])["index"]


# -- the header: the same refusals for each study (open_folder), shown on the fastest ------------------

SWEEP = ("sweep", *STUDIES["sweep"][0], *COMMON)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sweep")
    assert run_cli(*SWEEP, "--out", out) == 0
    return out


@pytest.mark.parametrize("header, words", [(None, ["holds points.jsonl but no sweep.json", "--force"]),
                                           ("[1, 2]\n", ["sweep.json cannot be read", "--force"]),
                                           ("{\"axes\": [", ["sweep.json cannot be read", "--force"])])
@pytest.mark.parametrize("again", [["--resume"], []])
def test_points_without_a_readable_header_are_refused_and_kept(sweep, tmp_path, capsys, header, words, again):
    shutil.copytree(sweep, tmp_path / "copy")
    if header is None:
        (tmp_path / "copy" / "sweep.json").unlink()
    else:
        (tmp_path / "copy" / "sweep.json").write_text(header)
    before = snapshot(tmp_path / "copy")
    capsys.readouterr()
    assert run_cli(*SWEEP, "--out", tmp_path / "copy", *again) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("piezo-fmu sweep: error: "), err
    if again or header is None:
        for word in words:
            assert word in err, (word, err)
    else:
        assert "already holds a sweep (2 of its points finished)" in err
    assert snapshot(tmp_path / "copy") == before


def test_resume_in_an_empty_folder_runs_the_study_afresh(sweep, tmp_path):
    assert run_cli(*SWEEP, "--out", tmp_path, "--resume") == 0
    records = [json.loads(line) for line in (tmp_path / "points.jsonl").read_text().splitlines()]
    assert sorted(record["index"] for record in records) == [0, 1]
    assert (tmp_path / "sweep.nc").stat().st_size > 0


# -- the chunked studies: each chunk checked against its own starts ----------------------------------

def chunk(number: int, starts: list[tuple[int, int]], **more) -> dict:
    """A chunk's record holding ``starts`` (``(index, group)``), each undecided."""
    return {"index": number, "starts": [{"index": i, "group": g, "label": -1, "periods": 10} for i, g in starts],
            "attractors": [], **more}


def test_every_chunk_of_a_basin_map_is_checked_against_its_own_starts():
    from piezo_fmu_harness.starts.chunks import chunks
    from piezo_fmu_harness.store import Damaged
    from piezo_fmu_harness.studies.basins.study import BasinSpec, record_check

    check = record_check(BasinSpec(1.2, 38.0, 1e-3, {}, (-1e-3, 1e-3, 33), (-0.1, 0.1, 33)))
    layout = chunks(33 * 33)
    assert len(layout) == 3
    for number, indices in enumerate(layout):
        check(chunk(number, [(i, 0) for i in indices]))
    with pytest.raises(Damaged, match="chunk 1 holds other starts"):
        check(chunk(1, [(i, 0) for i in layout[2]]))


def test_every_chunk_of_a_fractions_study_is_checked_against_its_frequencies_and_starts():
    from piezo_fmu_harness.store import Damaged
    from piezo_fmu_harness.studies.fractions.study import FractionSpec, record_check

    spec = FractionSpec((1.15, 1.175, 1.2), 31.6, (1e-3,) * 3, {"d": 8e-3}, 300, 8e-3, 0)
    check = record_check(spec)
    assert spec.chunks() == [[0, 1], [2]]
    for number, frequencies in enumerate(spec.chunks()):
        check(chunk(number, [(f * 300 + k, f) for f in frequencies for k in range(300)], frequencies=frequencies,
                    cycles=1))
    with pytest.raises(Damaged, match="frequencies"):
        check(chunk(1, [(600 + k, 2) for k in range(300)], frequencies=[1], cycles=1))
    with pytest.raises(Damaged, match="chunk 1 holds other starts"):
        check(chunk(1, [(300 + k, 1) for k in range(300)], frequencies=[2], cycles=1))


# -- a continuation resumed: its recorded branches replayed ------------------------------------------

def fake_chain(instance, problem: dict, steady: dict, lams: list, direction: str) -> dict:
    """A sweep of the seeds without the FMU: a stable orbit at every value, of order 1 below 1.2."""
    return {"direction": direction, "records": [
        {"lam": lam, "settled": True, "verdict": "stable", "state": [0.0] * 4, "phase": 0.0, "impacts_per_cycle": 2,
         "order": 1 if lam < 1.2 else 2, "amplitude": 1e-3 * lam, "unstable_orbits": [], "status": "ok"}
        for lam in lams]}


def fake_branch(instance, problem: dict, settings: dict, seed: dict) -> dict:
    """A branch without the FMU: the seed's orbit over +-0.15 of its value, and a doubled seed once."""
    lams = [seed["lam"] + step for step in (-0.15, 0.0, 0.15)]
    doubled = [{**seed, "order": 2 * seed["order"], "depth": 1}] if seed.get("depth", 0) == 0 else []
    return {"seed": seed, "points": [{"lam": lam, "amplitude": 1e-3 * lam, "order": seed["order"]} for lam in lams],
            "events": [], "seeds": doubled, "ends": ["left the band", "left the band"], "evaluations": 3}


def continuation(monkeypatch):
    from piezo_fmu_harness.periodic.steady_state import Settings as Steady
    from piezo_fmu_harness.studies.continuation import study as cs
    from piezo_fmu_harness.studies.continuation.tracer import Problem, Settings

    monkeypatch.setattr(cs, "seed_chain", fake_chain)
    monkeypatch.setattr(cs, "trace_branch", fake_branch)
    problem = Problem(values={}, parameter="ratio", bounds=(0.5, 2.0), natural=31.6)
    return cs.Continuation(problem, Settings(), Steady(), [0.5 + 0.1 * k for k in range(16)], 12)


def test_a_continuation_killed_among_its_branches_resumes_to_the_branches_it_would_have_followed(monkeypatch):
    """Which seed a branch starts from depends on the branches finished before it: replaying the
    recorded ones in their order gives the study the same state, and the branches that were running
    when it stopped run again; the result is the uninterrupted run's, branch for branch."""
    from piezo_fmu_harness.engine import InProcess

    whole, kept = continuation(monkeypatch), []
    whole.run(InProcess(None), log=kept.append, progress=False)
    assert len(whole.branches) >= 4 and len(kept) == 2 + len(whole.branches)

    def killed_after(count: int):
        def log(record: dict) -> None:
            if len(written) == count:
                raise KeyboardInterrupt
            written.append(json.loads(json.dumps(record)))  # as points.jsonl keeps it
        written: list = []
        return log, written

    log, written = killed_after(4)
    with pytest.raises(KeyboardInterrupt):
        continuation(monkeypatch).run(InProcess(None), log=log, progress=False)
    resumed, more = continuation(monkeypatch), []
    resumed.run(InProcess(None), recorded=tuple(written), log=more.append, progress=False)
    assert len(more) == len(kept) - 4  # only what was not recorded ran
    assert [b["seed"] for b in resumed.branches] == [b["seed"] for b in whole.branches]
    assert [b["points"] for b in resumed.branches] == [b["points"] for b in whole.branches]
    assert resumed.skipped == whole.skipped


@pytest.mark.parametrize("study", ["load-sweep", "bifurcation"])
def test_a_run_killed_midway_finishes_from_its_records_to_the_results_of_one_run(finished_runs, study, tmp_path):
    """The records of a killed run (its first half) are kept, and ``--resume`` runs the rest: the
    results are those of the run that was never interrupted."""
    folder = finished_runs[study]
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    lines = (copy / "points.jsonl").read_text().splitlines(keepends=True)
    (copy / "points.jsonl").write_text("".join(lines[:len(lines) // 2]))
    assert resume(study, copy) == 0
    table = {"load-sweep": "load_sweep.csv", "bifurcation": "bifurcation.csv"}[study]
    assert (copy / table).read_text() == (folder / table).read_text()
    assert len((copy / "points.jsonl").read_text().splitlines()) == len(lines)


@pytest.fixture(scope="module")
def finished_runs(tmp_path_factory) -> dict:
    runs = {}
    for study in ("load-sweep", "bifurcation"):
        runs[study] = tmp_path_factory.mktemp(study)
        assert run_cli(study, *STUDIES[study][0], *COMMON, "--out", runs[study]) == 0
    return runs


# -- a command that writes at its end: its folder, refused unless --force -----------------------------

SHORT = {"nominal": ("--stop-time", 0.05), "impact-voltage": ("--load", 52e3, "--models", 0),
         "two-designs": ("--stop-time", 0.05)}


@pytest.mark.parametrize("command", list(SHORT))
def test_a_folder_that_holds_a_run_is_refused_unless_force(command, tmp_path, capsys):
    argv = (command, *SHORT[command], "--fmu", FMU, "--out", tmp_path)
    assert run_cli(*argv) == 0
    before = snapshot(tmp_path)
    capsys.readouterr()
    assert run_cli(*argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"piezo-fmu {command}: error: --out {tmp_path} already holds a ") and "--force" in err, err
    assert snapshot(tmp_path) == before
    (tmp_path / "notes.txt").write_text("mine")
    assert run_cli(*argv, "--force") == 0
    assert (tmp_path / "notes.txt").read_text() == "mine"  # what the command does not write stays
