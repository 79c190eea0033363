"""The command line's surface: every subcommand and the option strings each takes, read from the
parser itself (not its help text, which wraps with the terminal's width)."""

from __future__ import annotations

import argparse


def surface(parser: argparse.ArgumentParser) -> dict:
    """``{"": top-level options, subcommand: sorted option strings (with each option's default and
    choices)}``."""
    def options(p: argparse.ArgumentParser) -> list:
        return sorted([sorted(a.option_strings), repr(a.default), sorted(a.choices) if isinstance(a.choices, (list, tuple))
                       else None, a.metavar] for a in p._actions if a.option_strings)

    found = {"": options(parser)}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found[name] = options(sub)
    return found


if __name__ == "__main__":  # python tests/cli_surface.py > tests/data/cli_surface.json
    import json

    from piezo_fmu_harness import cli

    print(json.dumps(surface(cli._parser()), indent=1))
