"""The kernel on an NVIDIA GPU: numba's CUDA target (the package ``numba-cuda``), one thread a
trajectory, one launch for a whole block of periods, no synchronisation inside it. Imported only
when a march on a GPU needs it (it imports numba's CUDA target)."""

from __future__ import annotations

from numba import config, cuda, float64

from .flat import march_one_flat
from .inputs import march_input_one
from .layout import WORK
from .periods import march_one, separate_one
from .registry import Target, entry

#: Threads a block of a launch.
THREADS = 128
#: Registers a thread may use: fewer than the compiler would take let more warps share a
#: multiprocessor, and the rest spill to cached local memory (measured: docs/benchmarks.md).
REGISTERS = 128


@entry(gpu=True)
def march(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    """Every trajectory of ``state`` through ``sections.shape[0]`` periods (:func:`.periods.march_one`)."""
    i = cuda.grid(1)
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)
        march_one(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)


@entry(gpu=True)
def march_flat(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    """:func:`march` by the flat loop (:func:`.flat.march_one_flat`): the same bits, faster on a GPU."""
    i = cuda.grid(1)
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)
        march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)


@entry(gpu=True)
def separate(state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms):
    """Every trajectory of ``state`` beside its companion (:func:`.periods.separate_one`)."""
    i = cuda.grid(1)
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)
        separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms,
                     work)


@entry(gpu=True)
def march_input(state, failed, stats, counts, ledger, nodes, slopes, hold, c, positions, onsets):
    """Every trajectory of ``state`` through a block of its own base input (:func:`.inputs.march_input_one`)."""
    i = cuda.grid(1)
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)
        march_input_one(i, state, failed, nodes, slopes, hold, c, positions, onsets, stats, counts, ledger, work)


def build(registers: int | None = REGISTERS) -> Target:
    """The GPU's target, its launches compiled for ``registers`` a thread (None: the compiler's
    choice; numba's CUDA simulator takes no limit)."""
    device = cuda.jit(device=True)
    launch = cuda.jit if config.ENABLE_CUDASIM or registers is None else cuda.jit(max_registers=registers)
    return Target(source=device, inline=device, gpu=launch)


def problem() -> str | None:
    """Why the kernel cannot run on a GPU here (None when it can)."""
    import numpy as np

    if not config.ENABLE_CUDASIM:
        try:  # what numba-cuda's first compilation imports: it fails there on a numpy it does not know
            import numba.cuda.cudaimpl  # noqa: F401
        except Exception as error:
            from importlib.metadata import PackageNotFoundError, version
            try:
                release = version("numba-cuda")
            except PackageNotFoundError:
                release = "?"
            return (f"device = 'gpu': numba-cuda {release} cannot compile with numpy "
                    f"{np.__version__} ({type(error).__name__}: {error}); install a numpy it supports (numba-cuda "
                    f"0.30.4 needs numpy < 2.5) or another numba-cuda; allowed devices here: 'cpu'")
    try:
        available = cuda.is_available()
    except Exception as error:  # the driver's own error
        available, error_text = False, f"{type(error).__name__}: {error}"
    else:
        error_text = "numba finds no CUDA GPU and driver"
    if not available:
        return f"device = 'gpu': {error_text}; allowed devices here: 'cpu'"
    return None
