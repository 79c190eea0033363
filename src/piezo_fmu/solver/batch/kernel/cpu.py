"""The kernel on the CPU: numba's ``njit``, every core, the compiled code kept on disk
(:mod:`.cache`). Imported only when a march needs it (it imports numba).

The ``prange`` loops run on numba's own thread pool (the ``workqueue`` layer) first, then OpenMP,
then TBB, unless ``NUMBA_THREADING_LAYER`` or ``NUMBA_THREADING_LAYER_PRIORITY`` say otherwise:
with TBB (Debian's libtbb 2021.8, numba 0.68) a process that marched many small batches hung at
its exit in ``tbb::finalize``, and a trajectory's bits do not depend on the layer.
"""

from __future__ import annotations

import os
import warnings

import numpy as np
from numba import config, njit, prange

from .cache import cache_dir, first_call_locked, install, unwritable, version_folder
from .flat import march_one_flat
from .inputs import march_input_one
from .layout import WORK
from .periods import march_one, separate_one
from .registry import Target, entry


@entry(parallel=True)
def march(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    """Every trajectory of ``state`` through ``sections.shape[0]`` periods (:func:`.periods.march_one`)."""
    for i in prange(state.shape[1]):
        work = np.empty(WORK)
        march_one(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)


@entry(parallel=True)
def march_flat(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    """:func:`march` by the GPU's flat loop (:func:`.flat.march_one_flat`): the same bits."""
    for i in prange(state.shape[1]):
        work = np.empty(WORK)
        march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)


@entry(parallel=True)
def separate(state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms):
    """Every trajectory of ``state`` beside its companion (:func:`.periods.separate_one`)."""
    for i in prange(state.shape[1]):
        work = np.empty(WORK)
        separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms,
                     work)


@entry(parallel=True)
def march_input(state, failed, stats, counts, ledger, nodes, slopes, hold, c, positions, onsets):
    """Every trajectory of ``state`` through a block of its own base input (:func:`.inputs.march_input_one`)."""
    for i in prange(state.shape[1]):
        work = np.empty(WORK)
        march_input_one(i, state, failed, nodes, slopes, hold, c, positions, onsets, stats, counts, ledger, work)


def build() -> Target:
    """The CPU's target (the thread pool chosen as the module's text says), its compiled code kept in :func:`.cache.cache_dir` (or, where that cannot
    be written, compiled for this process alone, with a warning that says so)."""
    if not {"NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY"} & set(os.environ):
        config.THREADING_LAYER_PRIORITY = ["workqueue", "omp", "tbb"]
    folder = version_folder(cache_dir())
    problem = unwritable(folder)
    if problem is None:
        install(folder)
    else:
        warnings.warn(f"piezo-fmu: the compiled kernel cannot be kept in {folder} ({problem}): it is compiled for "
                      "this process alone (about 10 s in every process); set NUMBA_CACHE_DIR to a writable folder "
                      "to keep it", RuntimeWarning, stacklevel=4)
    cache = problem is None
    # The inner functions touch no reference-counted object: without numba's runtime (``_nrt``)
    # their array arguments are not counted at every call, which cost more than the physics.
    inner = dict(cache=cache, error_model="numpy", _nrt=False, no_cpython_wrapper=True)

    def entry(**options):
        """The compiler of entry points: kept in the cache, their first call locked against other
        processes compiling into it (:class:`.cache.first_call_locked`)."""
        jit = njit(cache=cache, error_model="numpy", **options)
        return (lambda function: first_call_locked(jit(function), folder)) if cache else jit

    return Target(source=njit(**inner), inline=njit(inline="always", **inner), parallel=entry(parallel=True),
                  serial=entry())
