"""The options that several studies share, each a function that adds them to a subcommand's
parser: the FMU and its parameters, the simulated time, the band of harmonic base motion, the
results folder, the workers and the engine."""

from __future__ import annotations

from pathlib import Path

from .spec import DEFAULT_STOP_TIME


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
                     help=f"communication step, s (default {step_default:g}; {step_help})")
    model_options(sub)


def band_options(sub, defaults: dict, newton: bool = True) -> None:
    """The harmonic base motion, the band of frequencies and the steady-state settings (Newton's
    iterations too, for the studies that shoot through the FMU)."""
    amplitude = sub.add_mutually_exclusive_group()
    amplitude.add_argument("--amplitude", type=float, default=None, metavar="M",
                           help="base displacement amplitude Y, m (default 1e-3)")
    amplitude.add_argument("--acceleration", type=float, default=None, metavar="M/S2",
                           help="base acceleration amplitude A, m/s^2 (then Y = A / w^2 at each frequency)")
    for option, kind, metavar, text in (
            ("--ratio-min", float, "R", f"lowest frequency, as w / sqrt(K/M) (default {defaults['ratios'][0]:g})"),
            ("--ratio-max", float, "R", f"highest frequency, as w / sqrt(K/M) (default {defaults['ratios'][1]:g})"),
            ("--count", int, "N", f"frequencies, evenly spaced (default {defaults['count']})"),
            ("--load", float, "OHM", "load R_load of each patch, Ohm (default 1/(omega_c C_p), near the optimum)"),
            ("--voltage-model", int, "N", "0 quasi-static (nothing harvested), 1 circuit one-way, 2 circuit "
                                          "coupled (default 1)"),
            ("--samples", int, "N", "communication steps per forcing period (default 64)"),
            ("--tolerance", float, "TOL", "steady state: the section returns within TOL * Y (default 1e-6)"),
            ("--max-cycles", int, "N", f"cap on the forcing cycles simulated per frequency (default "
                                       f"{defaults['max_cycles']})"),
            ("--newton-iterations", int, "N", "Newton iterations per shooting attempt; 0 marches in time only "
                                              "(default 12)")):
        if option != "--newton-iterations" or newton:
            sub.add_argument(option, type=kind, default=None, metavar=metavar, help=text)


def results_folder(sub, name: str) -> None:
    """``--out``, by default ``results/NAME``."""
    sub.add_argument("--out", type=Path, default=Path("results") / name, metavar="DIR",
                     help=f"results folder (default results/{name})")


def jobs(sub) -> None:
    """``--jobs``."""
    sub.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")


def engine(sub) -> None:
    """Where the points run, and what to do with a folder that holds some already."""
    jobs(sub)
    where = sub.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
    where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")
    again = sub.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true",
                       help="finish the run in --out: run only the points not yet recorded")
    again.add_argument("--force", action="store_true", help="start over, discarding the points in --out")
    sub.add_argument("--no-progress", action="store_true", help="no progress bar")


def engine_once(sub) -> None:
    """Where the work runs, for a study that writes its results at its end (no ``--resume``):
    ``--jobs``, ``--scheduler`` or ``--dask-local``, and ``--force`` to replace them."""
    jobs(sub)
    where = sub.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler")
    where.add_argument("--dask-local", action="store_true", help="run on a local dask.distributed cluster")
    sub.add_argument("--force", action="store_true", help="replace the results in --out")


def time_series(sub, name: str) -> None:
    """The options of a study that writes one run's time series: its duration, its sampling
    (default :data:`piezo_fmu_harness.series.NOMINAL_STEP`), the model's options and ``--out``."""
    from .series import NOMINAL_STEP

    common(sub, NOMINAL_STEP, "the time series' sampling")
    results_folder(sub, name)


def many_start_options(sub, max_cycles: int, confirm: int, confirm_where: str) -> None:
    """The options of a study of many starts on the batch engine."""
    for option, kind, metavar, text in (
            ("--load", float, "OHM", "load R_load of each patch, Ohm (default 1/(omega_c C_p))"),
            ("--voltage-model", int, "N", "0, 1 or 2 (default 1)"),
            ("--samples", int, "N", "communication steps per forcing period (default 64)"),
            ("--tolerance", float, "TOL", "steady state: the section returns within TOL * Y (default 1e-6)"),
            ("--max-cycles", int, "N", f"the budget: forcing periods a start is marched at most; one not resolved by "
                                       f"then is reported undecided (default {max_cycles})")):
        sub.add_argument(option, type=kind, default=None, metavar=metavar, help=text)
    batch_options(sub, confirm, confirm_where)


def batch_options(sub, confirm: int, confirm_where: str) -> None:
    """Where the batch engine runs, and how many of its answers the FMU checks."""
    sub.add_argument("--confirm", type=int, default=None, metavar="N",
                     help=f"starts checked through the FMU besides one per attractor, {confirm_where} (default {confirm})")
    sub.add_argument("--seed", type=int, default=None, metavar="S",
                     help="seed of the random starts and of the FMU's sample (default 0)")
    sub.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                     help="where the batch engine's compiled kernel runs: every CPU core (numba), or an NVIDIA GPU "
                          "(numba's CUDA target, package numba-cuda; default cpu)")
