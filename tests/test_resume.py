"""``--resume`` on a damaged results folder (issue 53): every study that resumes (sweep,
frequency-response, optimize, basins, fractions), each run once at its smallest, then resumed from
a copy of its folder with one line spoiled. A line that is not JSON, a record without the study's
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
