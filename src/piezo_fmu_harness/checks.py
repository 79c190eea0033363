"""The shared steps of the ``piezo-fmu`` commands: reading the FMU, checking options (each bad one
a :class:`~piezo_fmu_harness.spec.UsageError` naming the option, the value and the allowed range),
the workers, and a first instance that accepts the start values."""

from __future__ import annotations

import math
from typing import Optional

from .spec import DEFAULT_STOP_TIME, UsageError

PROG = "piezo-fmu"


def open_model(args):
    from .fmu import FmuModel, default_fmu_path

    try:
        path = args.fmu or default_fmu_path()
        return FmuModel(path)
    except FileNotFoundError as error:
        raise UsageError(str(error)) from None
    except Exception as error:  # noqa: BLE001 - any unreadable FMU is bad input
        raise UsageError(f"--fmu {path}: cannot read the FMU: {error}") from None


def assignments(model, texts: list[str]) -> dict:
    from .spec import parse_assignment

    return dict(parse_assignment(model, text) for text in texts)


def times(args, step_default: float, config: Optional[dict] = None) -> tuple[float, float]:
    from .spec import check_times

    config = config or {}
    stop_time = args.stop_time if args.stop_time is not None else config.get("stop_time", DEFAULT_STOP_TIME)
    step = args.step if args.step is not None else config.get("step", step_default)
    check_times(stop_time, step)
    return stop_time, step


def preflight(model, values_list: list[dict], where: str):
    """Extract the FMU, let one instance accept ``values_list``; return ``(unzipdir, instance)``."""
    from .fmu import Instance, discard
    from .spec import check_with_fmu

    unzipdir = model.extract()
    instance = Instance(model, unzipdir)
    try:
        check_with_fmu(model, instance, values_list, where)
    except UsageError:
        instance.free()
        discard(unzipdir)
        raise
    return unzipdir, instance


def positive(value: float, option: str, what: str, unit: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"{option} {value:g}: {what} must be a finite number > 0; allowed range (0, inf) {unit}")
    return value


def device(name: str, why_not) -> str:
    """``--device NAME``, refused when ``why_not(NAME)`` (the batch engine's own test of the device)
    says why it cannot run here."""
    message = why_not(name)
    if message:
        raise UsageError(f"--device {name}: {message}")
    return name


def whole(value: int, option: str, lowest: int, what: str) -> int:
    if value < lowest:
        raise UsageError(f"{option} {value}: {what}; allowed range [{lowest}, inf)")
    return value


def load_value(model, value: float, option: str) -> float:
    """A load for ``R_load``: finite and > 0 (log spacing), within the modelDescription's bounds."""
    parameter = model.parameters["R_load"]
    if not (value > 0 and value < float("inf")):
        raise UsageError(f"{option} {value:g}: R_load = {value:g} Ohm must be a finite resistance > 0; "
                         "allowed range (0, inf) Ohm")
    try:
        return float(parameter.coerce(value))
    except ValueError as error:
        raise UsageError(f"{option} {value:g}: {error}") from None


def engine_damper(values: dict, batch, ratios=(), samples: int = 64) -> None:
    """The damper ``values`` (the FMU's defaults and ``--set``) forced at the study's frequencies
    ``ratios`` (``w / sqrt(K/M)``) with ``samples`` hold steps a period, refused before any work when the batch
    engine ``batch`` (the FMU's copy) says why the studies cannot take it: its contact's modes are
    not distinct to its closed form (two coincide, or their time scales lie too far apart), or the
    FMU that checks the studies would refuse their hold steps. Without ``ratios`` (a study that is not
    forced periodically) the contact alone is tested. An older engine tests the contact alone
    (``damper_error``), or nothing."""
    if hasattr(batch, "study_error"):
        message = batch.study_error(values, [float(r) for r in ratios], samples)
    else:
        message = batch.damper_error(values) if hasattr(batch, "damper_error") else None
    if message:
        raise UsageError(f"--set: {message}")


def worker_count(args) -> int:
    from .engine import default_jobs

    jobs = args.jobs if args.jobs is not None else default_jobs()
    return whole(jobs, "--jobs", 1, "need at least 1 worker")


def make_backend(args, model, unzipdir: str, jobs: int):
    """The engine's backend the options ask for: a Dask cluster, or a pool of ``jobs`` processes."""
    from .engine import DaskCluster, ProcessPool

    if args.scheduler or args.dask_local:
        try:
            return DaskCluster(model, args.scheduler, jobs)
        except (OSError, TimeoutError) as error:
            raise UsageError(f"--scheduler {args.scheduler}: cannot reach the Dask scheduler ({error})") from None
    return ProcessPool(model, unzipdir, jobs)


def interrupt(signum, frame):
    raise KeyboardInterrupt
