"""``piezo-fmu --help`` and every subcommand's ``--help`` list the same commands and options, with
the same defaults, choices and metavars, as captured before the harness was arranged by study
(issue 22): ``tests/data/cli_surface.json``, written by ``python tests/cli_surface.py``."""

from __future__ import annotations

import json
from pathlib import Path

from cli_surface import surface

from piezo_fmu_harness import cli

CAPTURED = Path(__file__).resolve().parent / "data" / "cli_surface.json"


#: Studies added after the capture (issues 23 and 26), in the order --help lists them.
ADDED = ("bifurcation", "basins", "fractions", "random")


def test_the_commands_are_those_captured_and_the_studies_added_since():
    captured = list(json.loads(CAPTURED.read_text()))
    live = list(surface(cli._parser()))
    assert [c for c in live if c not in ADDED] == captured
    assert set(live) - set(captured) == set(ADDED)


def test_every_command_takes_the_options_captured_with_their_defaults():
    captured = json.loads(CAPTURED.read_text())
    live = json.loads(json.dumps(surface(cli._parser())))
    for command, options in captured.items():
        assert live[command] == options, command
