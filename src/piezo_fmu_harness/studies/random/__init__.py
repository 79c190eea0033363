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

#: The kinds ``--psd`` names (anything else is a CSV file's path).
PSD_KINDS = ("white", "kanai-tajimi", "clough-penzien")
#: The spectrum's level by default, (m/s^2)^2/Hz: Kanai-Tajimi firm soil of RMS 0.28 m/s^2 (0.03 g), whose
#: response without the damper (RMS 3.3 mm for the nominal damper) reaches the 8 mm gap.
DEFAULT_LEVEL = 0.01
#: White noise's band by default, Hz.
DEFAULT_BAND = (0.5, 25.0)
#: The input's step by default: this many steps a period of the spectrum's highest frequency.
STEPS_PER_TOP = 10


def register(commands) -> None:
    """``piezo-fmu random``."""
    from ...options import batch_options, model_options, results_options, shared, work_options
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
    source = sub.add_mutually_exclusive_group()
    source.add_argument("--psd", default="kanai-tajimi", metavar="{white,kanai-tajimi,clough-penzien,FILE.csv}",
                        help="the PSD of the base acceleration: a kind, or a CSV table (frequency Hz, PSD (m/s^2)^2/Hz, "
                             "interpolated log-log) (default kanai-tajimi)")
    source.add_argument("--record", type=str, default=None, metavar="FILE.csv",
                        help="a recorded base acceleration instead (time s, acceleration m/s^2, a uniform step): one "
                             "realization")
    levels = sub.add_mutually_exclusive_group()
    levels.add_argument("--level", type=float, default=None, metavar="G0",
                        help="the PSD's level, one-sided, (m/s^2)^2/Hz: white noise's and the ground filters' G0, a "
                             f"table's largest value (default {DEFAULT_LEVEL:g}; a table as it is)")
    levels.add_argument("--levels", type=str, default=None, metavar="G1,G2,...",
                        help="several levels: the effectiveness curve (the same realizations, scaled)")
    sub.add_argument("--band", type=float, nargs=2, default=None, metavar=("FMIN", "FMAX"),
                     help="Hz: white noise's band; for the ground filters and a table, 0 and the cut (default "
                          f"{DEFAULT_BAND[0]:g} {DEFAULT_BAND[1]:g} for white noise, 0 25 for the ground filters, a "
                          "table's last frequency)")
    sub.add_argument("--soil", choices=("firm", "medium", "soft"), default="firm",
                     help="the ground filters' preset (Kanai-Tajimi, Clough-Penzien) (default firm)")
    for option, metavar, text in (("--omega-g", "RAD/S", "the ground's frequency, rad/s (default the soil's)"),
                                  ("--zeta-g", "Z", "the ground's damping ratio (default the soil's)"),
                                  ("--omega-f", "RAD/S", "Clough-Penzien's high-pass frequency, rad/s (default the soil's)"),
                                  ("--zeta-f", "Z", "Clough-Penzien's high-pass damping ratio (default the soil's)")):
        sub.add_argument(option, type=float, default=None, metavar=metavar, help=text)
    sub.add_argument("--envelope", type=str, default=None, metavar="KIND:P1,P2[,P3]",
                     help="modulate the acceleration like an earthquake: jennings:T1,T2,C (rise to T1 s, strong "
                          "motion to T2 s, decay e^-C(t-T2)) or shinozuka:B1,B2 (e^-B1 t - e^-B2 t, peak 1)")
    sub.add_argument("--realizations", type=int, default=None, metavar="N",
                     help=f"realizations (default {study.DEFAULT_REALIZATIONS}; 1 with --record)")
    sub.add_argument("--duration", type=float, default=None, metavar="S",
                     help="the window analysed, s, after the warm-up (default "
                          f"{study.DEFAULT_DURATION:g}; a record's length less the warm-up)")
    sub.add_argument("--warmup", type=float, default=None, metavar="S",
                     help="the warm-up discarded, s (default: until the linear oscillator's transient variance is 0.1%% "
                          "of its stationary one, ln(1000) / (2 zeta w_n); 0 with --record)")
    sub.add_argument("--step", type=float, default=None, metavar="S",
                     help=f"communication step, s (default {STEPS_PER_TOP} steps a period of the spectrum's highest "
                          "frequency; a record's own)")
    sub.add_argument("--f-low", type=float, default=None, metavar="HZ",
                     help="the high-pass corner of the low-frequency treatment, Hz (default 0.1, or half the band's "
                          "start where lower)")
    sub.add_argument("--save-input", type=int, default=None, metavar="K",
                     help="write realization K's input at the first level as input_K.csv (time, base_displacement, "
                          "base_velocity at each step's start, as fmpy's input= takes them) and its response with the "
                          "damper as response_K.csv")
    shared(sub, "--load")
    sub.add_argument("--voltage-model", type=int, default=None, metavar="N",
                     help="0 quasi-static (nothing harvested), 1 circuit one-way, 2 circuit coupled (default 2; "
                          "this study takes 0 or 2)")
    batch_options(sub, study.DEFAULT_CONFIRM)
    model_options(sub)
    results_options(sub, "random", resumable=True)
    work_options(sub)
    sub.set_defaults(run=command)


def command(args) -> int:
    from .command_line import run

    return run(args)
