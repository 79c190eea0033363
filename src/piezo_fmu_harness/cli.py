"""``piezo-fmu``: the piezo-impact damper's studies, each a command, run through its FMU with fmpy.

    piezo-fmu COMMAND [options]      # results in results/COMMAND, or --out DIR
    piezo-fmu COMMAND --help         # its options, each with its unit and default
    piezo-fmu --version

The commands (``piezo-fmu --help`` lists them, one line each): the paper's studies (``nominal``,
``sweep``, ``two-designs``, ``load-sweep``, ``impact-voltage``), the forced response
(``frequency-response``, ``continuation``), the studies of many starts on the batch engine
(``bifurcation``, ``basins``, ``fractions``), the optimiser (``optimize``) and ``presets``.

They share one convention (:mod:`piezo_fmu_harness.options`, docs/harness.md): values are SI (m,
kg, s, V); ``--out DIR`` refuses a folder that holds another run unless ``--force``; a long command
takes ``--resume`` (finish the run recorded in ``--out``), ``--no-progress`` and ``--jobs``, and
``--scheduler`` or ``--dask-local`` where its work is tasks. Bad input (an unknown parameter, an
empty or reversed range, a value outside the bounds of the FMU's modelDescription, an unwritable or
occupied output folder) is reported before anything runs, with exit status 2. An interrupted run
exits with 130 and keeps what it recorded; the same command with ``--resume`` finishes it.
"""

from __future__ import annotations

import argparse
import sys
from typing import Optional

from .checks import PROG
from .spec import UsageError


def version() -> str:
    """The installed package's version (``unknown`` when it runs from a source tree not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("piezo-fmu")
    except PackageNotFoundError:
        return "unknown"


class _OneLineEach(argparse.RawDescriptionHelpFormatter):
    """argparse's formatter, with each command's help on its name's line: argparse measures the
    commands' names two columns short of where it prints them, and a name as long as
    ``frequency-response`` then takes a line of its own."""

    def add_argument(self, action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction):
            longest = max(len(name) for name in action.choices)
            self._action_max_length = max(self._action_max_length, longest + self._current_indent + 4)


def _parser() -> argparse.ArgumentParser:
    """The parser: each study adds its subcommands (:data:`piezo_fmu_harness.studies.REGISTRY`)."""
    from .studies import REGISTRY

    parser = argparse.ArgumentParser(
        prog=PROG, description=" ".join(__doc__.split("\n\n")[0].replace("``", "").split()),
        epilog=f"Each command writes its results in results/COMMAND unless --out DIR says\notherwise; "
               f"'{PROG} COMMAND --help' lists its options, each with its unit\nand default.",
        formatter_class=lambda prog: _OneLineEach(prog, max_help_position=26))
    parser.add_argument("--version", action="version", version=f"{PROG} {version()}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    for register in REGISTRY:
        register(commands)
    return parser


def main(argv: Optional[list[str]] = None) -> int:
    """Run the CLI; return the exit status (0 done, 2 bad input, 130 interrupted)."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse has printed its message
        return int(exit_.code or 0)
    try:
        return args.run(args)
    except UsageError as error:
        print(f"{PROG} {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
