"""The command line's convention, written once: every option that more than one command takes is
added by one function here, with one help text, so that a name means one thing wherever it appears
(``tests/test_cli_convention.py`` walks the parser to hold it; docs/harness.md states it).

- :func:`results_options`: ``--out`` (``results/COMMAND``) and ``--force``; for a long command also
  ``--resume`` and ``--no-progress``. The rule for the folder is
  :func:`piezo_fmu_harness.store.open_folder` (a resumable run) or
  :func:`piezo_fmu_harness.store.claim_folder` (a short one).
- :func:`work_options`: ``--jobs``, and ``--scheduler`` / ``--dask-local`` where the work is tasks.
- :func:`drive_options`: the harmonic base motion, ``--amplitude`` or ``--acceleration``.
- :func:`band_options`: a band of frequencies and how a steady state is found at each.
- :func:`many_start_options`: a study of many starts on the batch engine: its budget
  (``--max-cycles``) and :func:`batch_options`, every batch study's FMU checks (``--confirm``),
  ``--seed`` and ``--device``.
- :func:`model_options`, :func:`common`: the FMU, its parameters, the simulated time.

A help text that states a default ends with ``(default ...)``. Some defaults are a study's own scale
(its folder, its band, its budget, its sampling of the FMU's checks); every other shared option has
one default everywhere.
"""

from __future__ import annotations

from pathlib import Path

from .spec import DEFAULT_STOP_TIME

#: The seed of every study's random draws.
DEFAULT_SEED = 0

#: The help of each shared option that takes a value: its type, metavar and meaning.
SHARED = {
    "--samples": (int, "N", "communication steps per forcing period (default 64)"),
    "--tolerance": (float, "TOL", "steady state: the section returns within TOL * Y (default 1e-6)"),
    "--load": (float, "OHM", "load R_load of each patch, Ohm (default 1/(omega_c C_p), near the optimum)"),
    "--voltage-model": (int, "N", "0 quasi-static (nothing harvested), 1 circuit one-way, 2 circuit coupled "
                                  "(default 1)"),
    "--newton-iterations": (int, "N", "Newton iterations per shooting attempt; 0 marches in time only (default 12)"),
}
RATIO = "as w / w_n, w_n = sqrt(K/M)"


def shared(sub, option: str, default: str = "", **more) -> None:
    """Add the shared ``option`` (:data:`SHARED`) to ``sub``; ``default``, when given, states the
    command's own default in place of the shared one (the voltage model of a study on the batch
    engine, which carries no one-way circuit)."""
    kind, metavar, text = SHARED[option]
    if default:
        text = f"{text.rpartition(' (default')[0]} (default {default})"
    sub.add_argument(option, type=kind, default=None, metavar=metavar, help=text, **more)


def model_options(sub) -> None:
    """``--set`` and ``--fmu``."""
    sub.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="set an FMU parameter (SI), repeatable")
    sub.add_argument("--fmu", type=Path, default=None,
                     help="the FMU (default $PIEZO_FMU, else the FMI 2.0 FMU installed with the package)")


def common(sub, step_default: float, step_help: str) -> None:
    """``--stop-time``, ``--step`` and the model's options."""
    sub.add_argument("--stop-time", type=float, default=None, metavar="S",
                     help=f"duration simulated, s (default {DEFAULT_STOP_TIME:g})")
    sub.add_argument("--step", type=float, default=None, metavar="S",
                     help=f"communication step, s (default {step_default:g}: {step_help})")
    model_options(sub)


def results_options(sub, name: str, resumable: bool, default: str = "") -> None:
    """``--out`` (by default ``results/NAME``; ``default`` says more when the default depends on
    other options) and ``--force``; with ``resumable``, ``--resume`` (exclusive of ``--force``) and
    ``--no-progress``."""
    sub.add_argument("--out", type=Path, default=None if default else Path("results") / name, metavar="DIR",
                     help=f"results folder; one that holds another run is refused unless --force "
                          f"(default results/{name}{default})")
    again = sub.add_mutually_exclusive_group()
    if resumable:
        again.add_argument("--resume", action="store_true",
                           help="finish the run recorded in --out: only what it has not recorded runs")
    again.add_argument("--force", action="store_true",
                       help="replace the run in --out: what it recorded is discarded")
    if resumable:
        sub.add_argument("--no-progress", action="store_true",
                         help="no progress bar (one is drawn on a terminal, over all the command's work)")


def work_options(sub, tasks: bool = True) -> None:
    """``--jobs``; with ``tasks`` (the work is tasks of the engine), ``--scheduler`` or ``--dask-local``."""
    sub.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")
    if tasks:
        where = sub.add_mutually_exclusive_group()
        where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
        where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")


def time_series(sub, name: str) -> None:
    """The options of a study that writes one run's time series: its duration, its sampling
    (default :data:`piezo_fmu_harness.series.NOMINAL_STEP`), the model's options, ``--out`` and
    ``--force``."""
    from .series import NOMINAL_STEP

    common(sub, NOMINAL_STEP, "the time series' sampling")
    results_options(sub, name, resumable=False)


def drive_options(sub) -> None:
    """The harmonic base motion: ``--amplitude`` or ``--acceleration``."""
    drive = sub.add_mutually_exclusive_group()
    drive.add_argument("--amplitude", type=float, default=None, metavar="M",
                       help="base displacement amplitude Y, m (default 1e-3)")
    drive.add_argument("--acceleration", type=float, default=None, metavar="M/S2",
                       help="base acceleration amplitude A, m/s^2, instead of --amplitude: Y = A / w^2 at each "
                            "frequency")


def frequency_options(sub, defaults: dict) -> None:
    """The band: ``--ratio-min``, ``--ratio-max`` and ``--count`` (the study's ``defaults``)."""
    lo, hi = defaults["ratios"]
    sub.add_argument("--ratio-min", type=float, default=None, metavar="R",
                     help=f"lowest frequency, {RATIO} (default {lo:g})")
    sub.add_argument("--ratio-max", type=float, default=None, metavar="R",
                     help=f"highest frequency, {RATIO} (default {hi:g})")
    count_option(sub, defaults["count"])


def count_option(sub, default: int) -> None:
    sub.add_argument("--count", type=int, default=None, metavar="N",
                     help=f"values of the swept range: frequencies evenly spaced, loads log-spaced (default {default})")


def ratio_option(sub, note: str = "", **more) -> None:
    """``--ratio``: the one frequency of a study, its default (``more``) said in the help by ``note``,
    unless ``more`` makes it required."""
    sub.add_argument("--ratio", type=float, metavar="R", help=f"the frequency, {RATIO}"
                     + (f" (default {note})" if note else ""), **more)


def band_options(sub, defaults: dict, newton: bool = True, voltage_model: str = "") -> None:
    """The harmonic base motion, the band of frequencies and how each steady state is found
    (Newton's iterations too, for the studies that shoot through the FMU); ``voltage_model``
    restates ``--voltage-model``'s default (:func:`shared`)."""
    drive_options(sub)
    frequency_options(sub, defaults)
    for option in ("--load", "--voltage-model", "--samples", "--tolerance"):
        shared(sub, option, voltage_model if option == "--voltage-model" else "")
    sub.add_argument("--cycles-per-frequency", type=int, default=None, metavar="N",
                     help="forcing periods simulated at most at one frequency: the search for its stable orbit, "
                          "Newton's runs and the checks of attraction and stability included; none found within "
                          f"them: undecided (default {defaults['max_cycles']})")
    if newton:
        shared(sub, "--newton-iterations")


def budget_option(sub, default: int) -> None:
    """``--max-cycles``: the budget of periods a start is marched."""
    sub.add_argument("--max-cycles", type=int, default=None, metavar="N",
                     help="the budget: forcing periods a start is marched at most; one that reaches no orbit "
                          f"within it is undecided (default {default})")


def seed_option(sub) -> None:
    """``--seed``: one seed for every random draw of a study."""
    sub.add_argument("--seed", type=int, default=DEFAULT_SEED, metavar="N",
                     help="seed of the study's random draws (its starts, the sample the FMU checks, the search's "
                          f"proposals): the same seed draws the same (default {DEFAULT_SEED})")


def many_start_options(sub, defaults: dict, confirm: int) -> None:
    """The options of a study of many starts on the batch engine: the drive, the circuit, the march
    (its budget ``defaults["max_cycles"]``), the FMU's checks, the seed and the device."""
    for option in ("--load", "--voltage-model", "--samples", "--tolerance"):
        shared(sub, option)
    budget_option(sub, defaults["max_cycles"])
    batch_options(sub, confirm)


def batch_options(sub, confirm: int) -> None:
    """The options of every study on the batch engine: how many of its answers the FMU checks beyond
    those it always checks (``confirm`` by default), the seed and the device."""
    sub.add_argument("--confirm", type=int, default=None, metavar="N",
                     help="more of the study's answers the FMU, marched alone, checks beyond those it always "
                          "checks, drawn with --seed (its section of docs/harness.md says which) "
                          f"(default {confirm})")
    seed_option(sub)
    sub.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                     help="where the batch engine's compiled kernel runs: every CPU core (numba), or an NVIDIA GPU "
                          "(numba's CUDA target, package numba-cuda) (default cpu)")


def damping_option(sub) -> None:
    """``--damping``: the damping measure that ranks designs."""
    sub.add_argument("--damping", choices=("eq29", "ls"), default="eq29",
                     help="the damping measure that ranks designs (the sweep's zones, the optimiser's perfectibility): "
                          "eq29, the paper's DI, or ls, DI_ls, the least-squares decay slope of the maxima "
                          "(default eq29)")


def models_option(sub, default: str) -> None:
    """``--models``: the voltage models a load study runs."""
    sub.add_argument("--models", default=default, metavar="LIST",
                     help="voltage models, comma-separated: 0 quasi-static (an open circuit: nothing harvested), "
                          f"1 circuit one-way, 2 circuit coupled (default {default})")
