"""``piezo-fmu --help`` and every subcommand's ``--help`` list the commands and options recorded in
``tests/data/cli_surface.json``, with the same defaults, choices and metavars: a change to the
command line is a change of that file, written by ``python tests/cli_surface.py`` (and told in
docs/harness.md and the changelog)."""

from __future__ import annotations

import json
from pathlib import Path

from cli_surface import surface

from piezo_fmu_harness import cli

RECORDED = Path(__file__).resolve().parent / "data" / "cli_surface.json"


def test_the_commands_are_those_recorded_in_the_order_help_lists_them():
    assert list(surface(cli._parser())) == list(json.loads(RECORDED.read_text()))


def test_every_command_takes_the_options_recorded_with_their_defaults():
    recorded = json.loads(RECORDED.read_text())
    live = json.loads(json.dumps(surface(cli._parser())))
    for command, options in recorded.items():
        assert live[command] == options, command
