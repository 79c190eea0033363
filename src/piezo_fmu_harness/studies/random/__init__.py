"""The damper under random base excitation (``piezo-fmu random``): under a spectrum of base
acceleration, by how much the damper reduces the main mass's response, how sure that is, and what it
harvests.

- :mod:`.command_line`: the options checked and turned into a spec
  (:mod:`piezo_fmu_harness.random_response`, which marches the realizations), the run;
- :mod:`.results`: the estimates at each level and the response PSD from the chunks;
- :mod:`.trace`: one realization step by step, on the batch engine and through the FMU alone;
- :mod:`.study`: the chunks as tasks, the FMU's checks, the files;
- :mod:`.figures`: the effectiveness curve, the response PSD, a time history, the peaks.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu random``."""
    from ...options import batch_options, model_options, results_options, shared, work_options
    from ...random_response.arguments import STEPS_PER_TOP, excitation_options
    from . import study

    sub = commands.add_parser(
        "random", help="the damper under random base excitation",
        description="March --realizations realizations of stationary Gaussian base acceleration of a one-sided PSD "
                    "(band-limited white noise, Kanai-Tajimi or Clough-Penzien ground motion, or a table), or a "
                    "recorded acceleration, with and without the damper on the same input, on the batch engine; "
                    "discard the warm-up and report per level the RMS of the main mass's displacement (relative and "
                    "absolute) with and without, their ratio with its 95% interval (paired over the "
                    "realizations), the peaks, the impacts a second, V_rms and the harvested power. The FMU "
                    "replays --confirm realizations. Writes random.nc, random.csv, psd.csv, summary.json, "
                    "effectiveness.png, psd.png, history.png and peaks.png (and input_K.csv, response_K.csv with "
                    "--save-input K); chunks of realizations are appended to points.jsonl (--resume).")
    source, levels = sub.add_mutually_exclusive_group(), sub.add_mutually_exclusive_group()
    excitation_options(sub, source, levels)
    source.add_argument("--record", type=str, default=None, metavar="FILE.csv",
                        help="a recorded base acceleration instead (time s, acceleration m/s^2, a uniform step): one "
                             "realization")
    levels.add_argument("--levels", type=str, default=None, metavar="G1,G2,...",
                        help="several levels: the effectiveness curve (the same realizations, scaled)")
    sub.add_argument("--envelope", type=str, default=None, metavar="KIND:P1,P2[,P3]",
                     help="modulate the acceleration like an earthquake: jennings:T1,T2,C (rise to T1 s, strong "
                          "motion to T2 s, decay e^-C(t-T2)) or shinozuka:B1,B2 (e^-B1 t - e^-B2 t, peak 1)")
    sub.add_argument("--step", type=float, default=None, metavar="S",
                     help=f"communication step, s (default {STEPS_PER_TOP} steps a period of the spectrum's highest "
                          "frequency; a record's own)")
    sub.add_argument("--save-input", type=int, default=None, metavar="K",
                     help="write realization K's input at the first level as input_K.csv (time, base_displacement, "
                          "base_velocity at each step's start, as fmpy's input= takes them) and its response with the "
                          "damper as response_K.csv")
    shared(sub, "--load")
    shared(sub, "--voltage-model", "2; this study takes 0 or 2")
    batch_options(sub, study.DEFAULT_CONFIRM)
    model_options(sub)
    results_options(sub, "random", resumable=True)
    work_options(sub)
    sub.set_defaults(run=command)


def command(args) -> int:
    from .command_line import run

    return run(args)
