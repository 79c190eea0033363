"""The command line's one convention (docs/harness.md, "One way to drive every study"), held by
walking the parser that ``piezo-fmu`` builds: every command writes to ``--out`` (``results/COMMAND``)
and refuses a folder holding another run unless ``--force``; every long command takes ``--resume``,
``--no-progress`` (and it works), ``--jobs``, ``--scheduler`` and ``--dask-local``; an option that
several commands take means one thing, with one help text and, but for a study's own scale, one
default; ``--version`` prints the package's version; the top-level help gives every command one
line; no help shows argparse's doubled ``%%``."""

from __future__ import annotations

import argparse
import re
import sys
from importlib.metadata import version
from pathlib import Path

import pytest
from fmu_host import run_cli

from piezo_fmu_harness import cli

FMU = Path(__file__).resolve().parent.parent / "fmus" / "PiezoImpactDamper.fmu"
#: The commands that write nothing.
NOTHING = ("presets",)
#: The commands that run for seconds and write their results at their end: ``--out`` and ``--force``.
SHORT = ("nominal", "two-designs", "impact-voltage")
#: What every other command, a long one, takes besides ``--out`` and ``--force``.
LONG = ("--resume", "--no-progress", "--jobs", "--scheduler", "--dask-local")
#: The options whose default is a study's own scale (its band, its budget, its folder, its sampling):
#: one meaning and one help text, the default stated in each command's help (docs/harness.md).
PER_STUDY = ("--out", "--ratio-min", "--ratio-max", "--count", "--max-cycles", "--cycles-per-frequency", "--step",
             "--ratio", "--models", "--load", "--confirm", "--voltage-model")
#: One name that two commands use for their own established idea: ``sweep --grid NAME=START:STOP:COUNT``
#: (a grid of parameters) and ``basins --grid N`` (N x N starts).
TWO_IDEAS = ("--grid",)
#: A help text's default: ``(default ...)`` at its end (one level of parentheses inside).
DEFAULT = re.compile(r"\s*\(default:? ((?:[^()]|\([^()]*\))*)\)$")


def commands() -> dict[str, argparse.ArgumentParser]:
    parser = cli._parser()
    found = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(found.choices)


def options(sub: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {option: action for action in sub._actions for option in action.option_strings if option.startswith("--")
            and option != "--help"}


def meaning(text: str) -> str:
    return DEFAULT.sub("", " ".join((text or "").split()))


def stated_default(text: str):
    found = DEFAULT.search(" ".join((text or "").split()))
    return found.group(1) if found else None


def test_every_command_writes_to_results_command_and_refuses_another_run_unless_force():
    for name, sub in commands().items():
        taken = options(sub)
        if name in NOTHING:
            assert "--out" not in taken, name
            continue
        out = taken["--out"]
        assert out.default in (Path("results") / name, None), name
        assert stated_default(out.help).startswith(f"results/{name}"), (name, out.help)
        assert meaning(out.help) == "results folder; one that holds another run is refused unless --force", name
        assert "--force" in taken, name


def test_every_long_command_resumes_shows_progress_and_runs_on_workers_or_dask():
    for name, sub in commands().items():
        if name in NOTHING + SHORT:
            continue
        missing = [option for option in LONG if option not in options(sub)]
        assert not missing, (name, missing)


def test_an_option_means_one_thing_wherever_it_appears():
    """The same name: the same help text (but its default), metavar, type and choices; and the same
    default, unless it is a study's own scale (:data:`PER_STUDY`), where each help states it."""
    seen: dict[str, list] = {}
    for name, sub in commands().items():
        for option, action in options(sub).items():
            seen.setdefault(option, []).append((name, action))
    shared = {option: uses for option, uses in seen.items() if len(uses) > 1 and option not in TWO_IDEAS}
    assert {"--seed", "--max-cycles", "--amplitude", "--out", "--resume", "--no-progress"} <= set(shared)
    for option, uses in shared.items():
        (first, action), rest = uses[0], uses[1:]
        for name, other in rest:
            where = (option, first, name)
            assert meaning(other.help) == meaning(action.help), where
            assert (other.metavar, other.type, other.choices, other.nargs) == \
                   (action.metavar, action.type, action.choices, action.nargs), where
            if option in PER_STUDY:
                assert stated_default(other.help) is not None or other.required, where
            else:
                assert other.default == action.default, where
                assert stated_default(other.help) == stated_default(action.help), where


def test_the_version_is_the_packages(capsys):
    assert run_cli("--version") == 0
    assert capsys.readouterr().out.strip() == f"piezo-fmu {version('piezo-fmu')}"


def test_the_top_level_help_gives_every_command_one_line(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    text = cli._parser().format_help()
    lines = text.splitlines()
    for name, sub in commands().items():
        line = next(k for k, row in enumerate(lines) if row.split()[:1] == [name])
        assert len(lines[line]) <= 80 and len(lines[line].split()) > 1, lines[line]  # its help on its own line
        assert not lines[line + 1].startswith(" " * 8), lines[line + 1]  # and not wrapped onto the next
    assert "bifurcation" in text.split("\n\n")[1] or "commands" in text


def test_no_help_shows_a_doubled_percent_sign():
    assert "%%" not in cli._parser().format_help()
    for name, sub in commands().items():
        assert "%%" not in sub.format_help(), name


#: What a progress bar shows: the time elapsed.
ELAPSED = re.compile(r"\[\d\d:\d\d")
#: Each long command at its smallest (and the FMU), for the progress bar.
SMALLEST = {
    "sweep": ("--grid", "m=0.02:0.2:2", "--stop-time", 0.2),
    "load-sweep": ("--r-min", 1e5, "--r-max", 1e7, "--count", 3, "--models", 1, "--stop-time", 0.2, "--no-impact"),
    "frequency-response": ("--set", "d=1", "--ratio-min", 1.9, "--ratio-max", 2.0, "--count", 2),
    "continuation": ("--set", "d=1", "--ratio-min", 1.9, "--ratio-max", 2.0, "--count", 2),
    "basins": ("--ratio", 1.2, "--grid", 2, "--confirm", 0),
    "fractions": ("--ratio-min", 1.2, "--ratio-max", 1.2, "--count", 1, "--starts", 2, "--confirm", 0),
    "optimize": ("--param", "m=0.05:0.2", "--maxiter", 1, "--popsize", 1, "--no-grid", "--stop-time", 0.5),
    "random": ("--realizations", 2, "--duration", 1, "--warmup", 0.5, "--confirm", 1),
}


@pytest.mark.parametrize("command", list(SMALLEST))
def test_no_progress_silences_the_bar_a_terminal_otherwise_shows(command, tmp_path, capsys, monkeypatch):
    """On a terminal a long command draws a progress bar over its work (the FMU's checks included:
    ``FMU checks``); ``--no-progress`` draws none."""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    argv = (command, *SMALLEST[command], "--jobs", 1, "--fmu", FMU)
    capsys.readouterr()
    assert run_cli(*argv, "--out", tmp_path / "bar") == 0
    drawn = capsys.readouterr().err
    assert ELAPSED.search(drawn), drawn  # a bar: the count (of a total, where known) and the time elapsed
    if command in ("basins", "fractions", "random"):
        assert "FMU checks: 100%" in drawn, drawn
    assert run_cli(*argv, "--out", tmp_path / "quiet", "--no-progress") == 0
    assert not ELAPSED.search(capsys.readouterr().err)
