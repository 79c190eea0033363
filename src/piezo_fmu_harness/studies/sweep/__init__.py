"""The sweep study (Figs. 4-9): a full-factorial grid of FMU parameters through the FMU, its
zones and contour figures (``piezo-fmu sweep`` and ``piezo-fmu presets``).

- :mod:`.run`: the sweep on the engine, its folder and results;
- :mod:`.analysis`: the Dataset, the design zones and their report;
- :mod:`.figures`: the contour figures and Figs. 4-9;
- :mod:`.presets`: the built-in sweeps;
- :mod:`.command`: the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

TOML_HELP = """

A --config file (SI units; the command line's --grid, --set, --stop-time and --step override it):

  stop_time = 2.0
  step = 0.1
  out = "results/x1-m"
  [grid]
  x1 = "0:0.03:31"                              # START:STOP:COUNT
  m = {start = 0.02, stop = 0.2, count = 31}
  # d = [0.004, 0.006, 0.008]                   # or explicit values, increasing
  [set]
  d = 0.008
"""


def register(commands) -> None:
    """``piezo-fmu sweep``."""
    from ...spec import DEFAULT_SWEEP_STEP
    from ...options import common, damping_option, results_options, work_options
    from . import presets
    from .command import sweep as run

    sweep = commands.add_parser(
        "sweep", help="a sweep over FMU parameters (Figs. 4-9)",
        description="Run every point of a full-factorial grid through the FMU; write sweep.nc, sweep.csv, zones.json "
                    "and the contour figures (DI.png, V_rms.png, P_ave.png, perfectibility.png; a preset set: "
                    "fig4.png to fig9.png); what was asked goes to sweep.json and each point to points.jsonl "
                    "(--resume). Presets:\n" + presets.describe() + TOML_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    common(sweep, DEFAULT_SWEEP_STEP, "the metrics do not depend on it")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=START:STOP:COUNT",
                       help="sweep a parameter over COUNT evenly spaced values (SI), repeatable")
    sweep.add_argument("--preset", choices=presets.preset_names(), metavar="NAME",
                       help=f"a built-in sweep: {', '.join(presets.preset_names())}")
    sweep.add_argument("--config", type=Path, metavar="FILE.toml",
                       help="grids and values from a TOML file ([grid], [set], stop_time, step, out)")
    results_options(sweep, "sweep", resumable=True, default="; results/PRESET with --preset")
    work_options(sweep)
    sweep.add_argument("--zone-quantile", type=float, default=None, metavar="Q",
                       help="our zones are the points at or above this quantile of each metric (default 0.9)")
    damping_option(sweep)
    sweep.set_defaults(run=run)


def register_presets(commands) -> None:
    """``piezo-fmu presets``: the built-in sweeps."""
    commands.add_parser("presets", help="list the built-in sweeps (writes nothing)",
                        description="List the built-in sweeps of `piezo-fmu sweep --preset NAME`.").set_defaults(
        run=_presets)


def _presets(args) -> int:
    from . import presets

    print(presets.describe())
    return 0
