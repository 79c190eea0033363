"""Continuation: the branches of periodic orbits of the forced response, followed
through their folds by pseudo-arclength continuation, with their stability and bifurcations
(``piezo-fmu continuation``).

- :mod:`.tracer`: the method, one branch at a time;
- :mod:`.branches`: a branch from a seed, its bifurcations, the period-doubled branches;
- :mod:`.study`: the seeds, the branches on the engine, the results and the command;
- :mod:`.figure`: the branches over the sweeps.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu continuation``."""
    from ...options import band_options, model_options, ratio_option, results_options, work_options
    from . import study as cs
    from .tracer import Settings

    continuation = commands.add_parser(
        "continuation", help="branches of periodic orbits through their folds",
        description="Seed with a sweep up and down (the frequency response's shooting, with the damper), then follow "
                    "every orbit with impacts by pseudo-arclength continuation in the frequency ratio (or Y, or a "
                    "damper parameter), through folds, naming the bifurcations (fold, period doubling, "
                    f"Neimark-Sacker, grazing). Writes {', '.join(cs.FILES)}; what was asked goes to "
                    "continuation.json and each sweep of the seeds and each branch to points.jsonl (--resume).")
    continuation.add_argument("--parameter", default="ratio", metavar="NAME",
                              help="the continued parameter: ratio (default), Y, or a Real damper parameter")
    continuation.add_argument("--range", default=None, metavar="LO:HI", help="its range (not for ratio)")
    ratio_option(continuation, "1; held fixed when the continued parameter is not the ratio", default=1.0)
    continuation.add_argument("--max-points", type=int, default=Settings().max_points, metavar="N",
                              help="points a branch may have in each direction (default %(default)s)")
    continuation.add_argument("--max-branches", type=int, default=cs.MAX_BRANCHES, metavar="N",
                              help="branches followed at most (default %(default)s)")
    band_options(continuation, cs.SEED_DEFAULTS)
    model_options(continuation)
    results_options(continuation, "continuation", resumable=True)
    work_options(continuation)
    continuation.set_defaults(run=cs.command)
