"""The compiled kernel: many trajectories of one damper marched period by period, each on its own
thread, with no Python in the loop.

**One source, two targets.** The kernel is written once, as scalar functions of one trajectory
(:mod:`.flows`, :mod:`.location`, :mod:`.switches`, :mod:`.rounds`, :mod:`.periods`, :mod:`.flat`),
registered where they are defined (:mod:`.registry`), and compiled as they are: with numba on the
CPU (:mod:`.cpu`: ``njit``, a ``prange`` loop over the trajectories, the code kept on disk by
:mod:`.cache`) and with numba's CUDA target on a GPU (:mod:`.gpu`: device functions, one thread a
trajectory, one launch for a whole block of periods; the flat loop of :mod:`.flat`). The rules that
let one source compile for both: scalars, tuples, ``math`` and arrays passed in, a scratch row of
:data:`.layout.WORK` floats; no allocation, no exception, no numpy call inside. A trajectory's work
does not depend on how many others march with it: alone or in a batch it gives the same bits.

The physics is that of :mod:`..model` (the closed forms and their bounds), with the switch rules
of :mod:`piezo_fmu.model.dynamics`; the scalar core (:mod:`piezo_fmu.solver`) is written apart,
and each is the other's check. numba is a dependency of the harness, not of the FMUs: nothing that
compiles is imported until a study marches.
"""

from __future__ import annotations

import threading

import numpy as np

from .layout import LEDGER, STATS
from .registry import Target
from .tables import Tables, input_hold

#: The devices the kernel runs on: the CPU (numba) and an NVIDIA GPU (numba's CUDA target).
DEVICES = ("cpu", "gpu")
#: How each device marches by default: the nested loops on the CPU, the flat loop on a GPU (the
#: same bits).
FLAT = {"cpu": False, "gpu": True}

_lock = threading.Lock()
_targets: dict = {}


def gpu_error() -> str | None:
    """Why the kernel cannot run on a GPU here (None when it can)."""
    try:
        from . import gpu
    except ImportError as error:
        return f"device = 'gpu': numba's CUDA target (the package numba-cuda) is needed ({error}); allowed devices here: 'cpu'"
    return gpu.problem()


def device_error(device: str) -> str | None:
    """Why the kernel cannot run on ``device`` here (None when it can)."""
    if device not in DEVICES:
        return f"device = {device!r} is not known; allowed values {DEVICES}"
    return gpu_error() if device == "gpu" else None


def target(device: str) -> Target:
    """The kernel compiled for ``device`` ("cpu" or "gpu"); a function is compiled on first use."""
    with _lock:
        if device not in _targets:
            error = device_error(device)
            if error:
                raise ValueError(error)
            if device == "gpu":
                from . import gpu
                _targets[device] = gpu.build()
            else:
                from . import cpu
                _targets[device] = cpu.build()
        return _targets[device]


def march(device: str, tables: Tables, state: np.ndarray, failed: np.ndarray, groups: np.ndarray,
          periods: int, observe: bool = True, flat: bool | None = None) -> dict:
    """March every trajectory of ``state`` ((7, n) host: ``p, p', q, q'``, side, left and right
    voltage; updated in place, as is ``failed``) ``periods`` periods. Returns host arrays:
    ``sections`` (periods, n, 4), ``sides`` and ``impacts`` (periods, n), and with ``observe``
    ``top`` and ``bottom`` (NaN without; on a GPU, a read-only view then, not copied back).
    ``flat`` chooses the flat loop or the nested one (the device's own, :data:`FLAT`, when None):
    the same bits."""
    n = state.shape[1]
    outputs = (np.empty((periods, n, 4)), np.empty((periods, n)), np.empty((periods, n), np.int64),
               np.empty((periods, n)), np.empty((periods, n)))
    flat = FLAT[device] if flat is None else flat
    args = (observe, state, failed, groups) + tables.arguments() + outputs
    # unobserved, the kernel writes NaN for the extremes: a GPU's need not be copied back
    entries = _entries(device)
    _launch(device, entries.march_flat if flat else entries.march, args, n, (1, 2), 5,
            kept=None if observe else len(args) - 2)
    sections, sides, impacts, top, bottom = outputs
    if not observe and device != "cpu":  # read-only, untouched memory
        top = bottom = np.broadcast_to(np.nan, (periods, n))
    return {"sections": sections, "sides": sides.astype(np.int64), "impacts": impacts, "top": top, "bottom": bottom}


def separate(device: str, tables: Tables, state: np.ndarray, failed: np.ndarray, groups: np.ndarray,
             offset: np.ndarray, scale: np.ndarray, delta: np.ndarray, periods: int) -> dict:
    """Each trajectory of ``state`` beside a companion ``offset`` ((4, n), updated) away,
    renormalised to ``delta`` (m, (n,), distances weighted by ``scale`` (4, n)) after every period,
    for ``periods`` periods (:func:`.periods.separate_one`). Returns host arrays (periods, n):
    ``logs`` (the log of each period's stretch), ``samples`` (``p`` at each section), ``impacts``,
    ``top`` and ``bottom``."""
    n = state.shape[1]
    outputs = (np.empty((periods, n)), np.empty((periods, n)), np.empty((periods, n), np.int64),
               np.empty((periods, n)), np.empty((periods, n)))
    args = (state, failed, groups, offset, np.ascontiguousarray(scale), np.ascontiguousarray(delta))
    _launch(device, _entries(device).separate, args + tables.arguments() + outputs, n, (0, 1, 3), 5)
    logs, samples, impacts, top, bottom = outputs
    return {"logs": logs, "samples": samples, "impacts": impacts, "top": top, "bottom": bottom}


def march_input(device: str, tables: Tables, hold: np.ndarray, state: np.ndarray, failed: np.ndarray,
                accumulators: tuple, nodes: np.ndarray, slopes: np.ndarray) -> tuple:
    """March every trajectory of ``state`` ((7, n), as :func:`march` takes it; updated in place, as is
    ``failed``) through a block of its own base input: ``nodes`` ((n, B + 1), m) and ``slopes``
    ((n, B), m/s), a trajectory's a row, and the hold step's constants ``hold``
    (:func:`.tables.input_hold`); ``accumulators`` ``(stats (n, STATS), counts (n,) int64, ledger (n,
    LEDGER))`` are added to (:mod:`.inputs`). Returns host arrays (n, B): ``positions``, ``p`` (m)
    at each step's end, and ``onsets``, the contact onsets in each step."""
    n = state.shape[1]
    positions, onsets = np.empty(slopes.shape), np.empty(slopes.shape, np.int32)
    args = (state, failed, *accumulators, np.ascontiguousarray(nodes, float), np.ascontiguousarray(slopes, float),
            np.ascontiguousarray(hold, float), tables.constants, positions, onsets)
    _launch(device, _entries(device).march_input, args, n, (0, 1, 2, 3, 4), 2)
    return positions, onsets


def accumulators(n: int) -> tuple:
    """Zeroed accumulators of :func:`march_input` for ``n`` trajectories."""
    return np.zeros((n, STATS)), np.zeros(n, np.int64), np.zeros((n, LEDGER))


def _entries(device: str):
    """The module of ``device``'s entry points (:mod:`.cpu` or :mod:`.gpu`)."""
    if device == "cpu":
        from . import cpu
        return cpu
    from . import gpu
    return gpu


def _launch(device: str, entry, args: tuple, n: int, updated: tuple, outputs: int, kept: int | None = None) -> None:
    """Run the entry point ``entry`` over ``n`` trajectories; on a GPU, copy the inputs there (the
    last ``outputs`` arguments are only allocated there: the kernel writes them whole) and the
    ``updated`` ones and the outputs back (those before the argument ``kept`` only, when given)."""
    compiled = target(device)(entry)
    if n == 0:
        return
    if device == "cpu":
        compiled(*args)
        return
    from numba import cuda

    from .gpu import THREADS
    first_output = len(args) - outputs
    on_device = [a if not isinstance(a, np.ndarray) else cuda.device_array_like(a) if k >= first_output
                 else cuda.to_device(np.ascontiguousarray(a)) for k, a in enumerate(args)]
    compiled[(n + THREADS - 1) // THREADS, THREADS](*on_device)
    for k in list(updated) + list(range(first_output, len(args) if kept is None else kept)):
        on_device[k].copy_to_host(args[k])
