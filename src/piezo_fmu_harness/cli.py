"""``piezo-fmu``: the nominal case, sweeps, the two designs, the load, the frequency response, its
continuation and the optimiser, all through the FMU with fmpy.

    piezo-fmu nominal [--out DIR] [--stop-time S] [--step S] [--set NAME=VALUE ...]
    piezo-fmu sweep (--grid NAME=START:STOP:COUNT ... | --preset NAME | --config FILE.toml)
                    [--set NAME=VALUE ...] [--stop-time S] [--step S] [--out DIR] [--jobs N]
                    [--scheduler ADDRESS | --dask-local] [--resume | --force] [--damping eq29|ls]
    piezo-fmu two-designs [--out DIR] [--stop-time S] [--step S]
    piezo-fmu load-sweep [--r-min OHM] [--r-max OHM] [--count N] [--models 1,2] [--set NAME=VALUE ...]
                         [--stop-time S] [--step S] [--impact-step S] [--out DIR] [--jobs N]
    piezo-fmu impact-voltage [--load OHM ...] [--models 0,1,2] [--step S] [--set NAME=VALUE ...] [--out DIR]
    piezo-fmu frequency-response [--amplitude M | --acceleration M/S2] [--ratio-min R] [--ratio-max R] [--count N]
                                 [--load OHM] [--voltage-model N] [--set NAME=VALUE ...] [--samples N]
                                 [--tolerance TOL] [--max-cycles N] [--newton-iterations N] [--out DIR]
                                 [--jobs N] [--scheduler ADDRESS | --dask-local] [--resume | --force]
    piezo-fmu continuation [--parameter ratio|Y|NAME] [--range LO:HI] [--ratio R] [--max-points N]
                           [--max-branches N] [frequency-response's band options] [--out DIR] [--jobs N]
                           [--scheduler ADDRESS | --dask-local] [--force]
    piezo-fmu optimize --param NAME=LO:HI ... [--objective perfectibility|forced] [--weight TERM=W ...]
                       [--reference TERM=VALUE ...] [--damping eq29|ls] [--maxiter N] [--popsize N] [--seed N]
                       [--polish] [--no-grid] [--sensitivity-step F] [frequency-response's band options]
                       [--out DIR] [--jobs N] [--scheduler ADDRESS | --dask-local] [--resume | --force]
    piezo-fmu presets

Values are SI (m, kg, s, V). Bad input (an unknown parameter, an empty or reversed range, a
value outside the bounds of the FMU's modelDescription, an unwritable output folder) is
reported before anything runs, with exit status 2. An interrupted sweep exits with 130 and
keeps every finished point; run the same command with ``--resume`` to finish it.
"""

from __future__ import annotations

import argparse
import sys
from typing import Optional

from .checks import PROG
from .spec import UsageError


def _parser() -> argparse.ArgumentParser:
    """The parser: each study adds its subcommands (:data:`piezo_fmu_harness.studies.REGISTRY`)."""
    from .studies import REGISTRY

    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
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
