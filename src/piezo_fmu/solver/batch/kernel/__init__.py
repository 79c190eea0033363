"""The compiled kernel (issue 32): :mod:`.kernel_source` compiled for the CPU and for a GPU.

**One source, two targets.** The scalar functions of :mod:`.kernel_source` are compiled as they
are: with numba on the CPU (``njit``, cached on disk, a ``prange`` loop over the trajectories) and
with numba's CUDA target on a GPU (``numba-cuda``: device functions, one thread a trajectory, one
launch for a whole block of periods, no synchronisation inside it). Each target gets its own copy
of the functions, whose globals name that target's compiled versions, so the source never says
which target it is on. A trajectory's work does not depend on how many others march with it: one
trajectory gives the same bits alone and in a batch.

numba is a dependency of the harness, not of the FMUs: nothing here is imported until a study
marches, and the FMUs' runtime never does.

**The disk cache.** The CPU code is compiled once per machine and kept in ``$NUMBA_CACHE_DIR`` or
else ``~/.cache/piezo-fmu/numba`` (``$XDG_CACHE_HOME`` respected), keyed by the source's content:
a process that imported ``piezo_fmu`` from an FMU's copy of the package (a host process loads the
FMU's own copy) finds the same compiled code as one that imported the installed package. Where that
folder cannot be written, the code is compiled for the process alone, with a warning that says so.
"""

from __future__ import annotations

import math
import os
import threading
import types
import warnings
from pathlib import Path

import numpy as np

from . import kernel_books as books
from . import kernel_flow as flow
from . import kernel_phases as physics
from . import kernel_source as source
from .phases import BatchModel

#: The functions of the source, in the order they are compiled (each calls only earlier ones).
FUNCTIONS = ("fmax", "fmin", "sign", "free_coefficients", "free_apply", "safe_step", "start_sign", "free_values",
             "contact_value", "locate_step", "locate", "free_start", "free_event", "contact_start", "contact_event",
             "contact_state", "round_start", "round_end", "contact_voltage", "event_rounds", "free_step", "hold_step",
             "hermite_extremes", "one_period", "march_one", "separate_one", "march_one_flat")
#: Small functions compiled into their callers on the CPU (a call of a compiled function costs
#: about as much as their work); the GPU compiler inlines device functions by itself.
INLINE = ("fmax", "fmin", "sign", "free_apply", "safe_step", "start_sign", "locate_step", "free_start", "contact_start",
          "round_start", "round_end", "contact_voltage", "free_step")
#: Threads a block of the GPU launch.
GPU_THREADS = 128
#: Registers a GPU thread may use: fewer than the compiler would take (142 for the flat march) let
#: more warps share a multiprocessor, and the rest spill to cached local memory. Measured on an H200
#: (``docs/benchmarks.md``), the flat march at a million starts: 55.6 million start-periods a second
#: uncapped, 61.6 at 128 registers, 57.8 at 96, 41.3 at 64 (the same bits at each).
GPU_REGISTERS = 128
#: How each target marches: the nested loops of :func:`.kernel_source.march_one` on the CPU, the
#: flat loop of :func:`.kernel_flow.march_one_flat` on a GPU (the same bits, see :mod:`.kernel_flow`).
FLAT = {"cpu": False, "gpu": True}

_lock = threading.Lock()
_targets: dict = {}


def cache_dir() -> Path:
    """Where the compiled CPU code is kept (see the module's text)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "piezo-fmu" / "numba"


def _copy(function, namespace: dict, name: str):
    clone = types.FunctionType(function.__code__, namespace, name, function.__defaults__)
    clone.__module__, clone.__qualname__, clone.__doc__ = function.__module__, name, function.__doc__
    return clone


def _compiled(jit, drivers: dict, inline=None) -> dict:
    """The source's functions compiled by ``jit`` (those of :data:`INLINE` by ``inline``, when
    given), and the ``drivers`` (name: (function, jit)) beside them, all with their globals in one
    namespace."""
    namespace = {k: v for module in (physics, source, flow) for k, v in vars(module).items() if not k.startswith("__")}
    for name in FUNCTIONS:
        compiler = inline if inline is not None and name in INLINE else jit
        namespace[name] = compiler(_copy(namespace[name], namespace, name))
    for name, (function, driver_jit) in drivers.items():
        namespace[name] = driver_jit(_copy(function, namespace, name))
    return namespace


# -- the CPU ---------------------------------------------------------------------------------------

def _march_cpu(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    for i in prange(state.shape[1]):  # noqa: F821 (a global of the compiled namespace)
        work = np.empty(WORK)  # noqa: F821
        march_one(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)  # noqa: F821


def _march_flat_cpu(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    for i in prange(state.shape[1]):  # noqa: F821
        work = np.empty(WORK)  # noqa: F821
        march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)  # noqa: F821


def _separate_cpu(state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms):
    for i in prange(state.shape[1]):  # noqa: F821
        work = np.empty(WORK)  # noqa: F821
        separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts,  # noqa: F821
                     tops, bottoms, work)


def _cpu() -> dict:
    import numba
    from . import kernel_cache
    files = (physics.__file__, source.__file__, flow.__file__, books.__file__, __file__)
    folder = kernel_cache.version_folder(files, cache_dir())
    problem = kernel_cache.unwritable(folder)
    if problem is None:
        kernel_cache.install(files, folder)
    else:
        warnings.warn(f"piezo-fmu: the compiled kernel cannot be kept in {folder} ({problem}): it is compiled for "
                      "this process alone (about 10 s in every process); set NUMBA_CACHE_DIR to a writable folder "
                      "to keep it", RuntimeWarning, stacklevel=3)
    cache = problem is None
    # The inner functions touch no reference-counted object: without numba's runtime (``_nrt``)
    # their array arguments are not counted at every call, which cost more than the physics.
    options = dict(cache=cache, error_model="numpy", _nrt=False, no_cpython_wrapper=True)
    jit, inline = numba.njit(**options), numba.njit(inline="always", **options)
    parallel = numba.njit(cache=cache, parallel=True, error_model="numpy")
    serial = numba.njit(cache=cache, error_model="numpy")
    drivers = {"march": (_march_cpu, parallel), "march_flat": (_march_flat_cpu, parallel),
               "separate": (_separate_cpu, parallel), "largest4": (books.largest4, inline),
               "shrinking_returns": (books.shrinking_returns, serial), "orbit_distances": (books.orbit_distances, serial),
               "free_for_ever_flags": (books.free_for_ever_flags, serial),
               "converging_orders": (books.converging_orders, serial)}
    namespace = _compiled(jit, drivers, inline)
    namespace.update(np=np, prange=numba.prange)
    return namespace


# -- the GPU ---------------------------------------------------------------------------------------

def _march_gpu(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    i = cuda.grid(1)  # noqa: F821
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)  # noqa: F821
        march_one(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)  # noqa: F821


def _march_flat_gpu(observe, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms):
    i = cuda.grid(1)  # noqa: F821
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)  # noqa: F821
        march_one_flat(observe, i, state, failed, groups, drive, c, sections, sides, impacts, tops, bottoms, work)  # noqa: F821


def _separate_gpu(state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts, tops, bottoms):
    i = cuda.grid(1)  # noqa: F821
    if i < state.shape[1]:
        work = cuda.local.array(WORK, float64)  # noqa: F821
        separate_one(i, state, failed, groups, offset, scale, delta, drive, c, logs, samples, impacts,  # noqa: F821
                     tops, bottoms, work)


def _gpu(registers: int | None = None) -> dict:
    """The GPU's namespace, its launches compiled for ``registers`` a thread (None: the compiler's
    choice); :func:`target` gives the one of :data:`GPU_REGISTERS`, ``bench_gpu.py --registers``
    compares others."""
    from numba import config, cuda, float64
    device = cuda.jit(device=True)
    # numba's CUDA simulator (the tests' GPU) takes no register limit
    launch = cuda.jit if config.ENABLE_CUDASIM or registers is None else cuda.jit(max_registers=registers)
    namespace = _compiled(device, {"march": (_march_gpu, launch), "march_flat": (_march_flat_gpu, launch),
                                   "separate": (_separate_gpu, launch)})
    namespace.update(cuda=cuda, float64=float64)
    return namespace


def gpu_error() -> str | None:
    """Why the kernel cannot run on a GPU here (None when it can)."""
    try:
        from numba import cuda
    except ImportError as error:
        return f"device = 'gpu': numba's CUDA target (the package numba-cuda) is needed ({error}); allowed devices here: 'cpu'"
    from numba import config
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


def target(device: str) -> dict:
    """The compiled namespace of ``device`` ("cpu" or "gpu"), compiled on first use."""
    with _lock:
        if device not in _targets:
            if device == "gpu":
                error = gpu_error()
                if error:
                    raise ValueError(error)
                _targets[device] = _gpu(GPU_REGISTERS)
            elif device == "cpu":
                _targets[device] = _cpu()
            else:
                raise ValueError(f"device = {device!r} is not known; allowed values ('cpu', 'gpu')")
        return _targets[device]


# -- the damper and the drives as the kernel takes them -----------------------------------------------

class Tables:
    """A damper and its drives packed for the kernel (host arrays, see :mod:`.kernel_source`)."""

    def __init__(self, model: BatchModel, drives: list):
        free, contact = model.free, model.contact
        if abs(free.beta2) <= 1e-12 * free.w2:
            mode, wd = physics.CRITICAL, 0.0
        elif free.beta2 < 0.0:
            mode, wd = physics.UNDERDAMPED, math.sqrt(-free.beta2)
        else:
            mode, wd = physics.OVERDAMPED, math.sqrt(free.beta2)
        values = {physics.A: free.a, physics.W2: free.w2, physics.BETA2: free.beta2, physics.CS_MODE: mode, physics.WD: wd,
                  physics.BOUND_RATE: free.bound_rate, physics.HG: model.half_gap, physics.MM: model.M,
                  physics.M1: model.M1, physics.MI: model.m, physics.M_EQ: model.M_eq, physics.KK: model.K,
                  physics.CC: model.C, physics.COUPLED: 1.0 if model.coupled else 0.0, physics.TAU_E: model.tau_e}
        n, modes = contact.size, physics.MODES
        used, weight = _modes(contact.lam)
        lam, lam2, gain = np.zeros(modes, complex), np.zeros(modes), np.zeros(modes, complex)
        qinv, qm = np.zeros((modes, modes), complex), np.zeros((modes, modes), complex)
        k = len(used)
        lam[:k], lam2[:k], gain[:k] = contact.lam[used], np.abs(contact.lam[used]) ** 2, contact.gain[used]
        qinv[:k, :n], qm[:n, :k] = contact.Q_inv[used, :], contact.Q[:, used]
        weights = np.zeros(modes)
        weights[:k] = weight
        parts = lambda z: [z.real.ravel(), z.imag.ravel()]  # noqa: E731
        self.constants = np.concatenate([[values[k] for k in range(physics.LAM)], *parts(lam), lam2, *parts(gain),
                                         *parts(qinv), *parts(qm), weights, [float(len(used))]])
        assert self.constants.shape == (physics.CONSTANTS,)
        h = np.array([drive.step for drive in drives])
        ec, es = free.coefficients(np, h)  # numpy's, as the array engine's
        nodes = [drive.nodes() for drive in drives]
        self.drive = np.ascontiguousarray(np.column_stack([h, ec, es, np.exp(-h / model.tau_e),
                                                           np.stack([y for y, _ in nodes]),
                                                           np.stack([v for _, v in nodes])]))

    def arguments(self) -> tuple:
        return self.drive, self.constants


def _modes(lam: np.ndarray) -> tuple[list, list]:
    """The contact's modes the kernel carries and their weights: each complex pair once (the one
    with the positive imaginary part, weight 2), each real mode with weight 1."""
    used, weight = [], []
    for k, value in enumerate(lam):
        if value.imag > 0.0:
            partner = np.abs(lam - np.conj(value)).argmin()
            if lam[partner].imag >= 0.0 or abs(lam[partner] - np.conj(value)) > 1e-12 * abs(value):
                raise AssertionError(f"contact: the eigenvalue {value} has no conjugate partner")
            used.append(k)
            weight.append(2.0)
        elif value.imag == 0.0:
            used.append(k)
            weight.append(1.0)
    return used, weight


def march(device: str, tables: Tables, state: np.ndarray, failed: np.ndarray, groups: np.ndarray,
          periods: int, observe: bool = True, flat: bool | None = None) -> dict:
    """March every trajectory of ``state`` ((7, n) host: ``p, p', q, q'``, side, left and right
    voltage; updated in place, as is ``failed``) ``periods`` periods. Returns host arrays:
    ``sections`` (periods, n, 4), ``sides`` and ``impacts`` (periods, n), and with ``observe``
    ``top`` and ``bottom`` (NaN without; on a GPU, a read-only view then, not copied back).
    ``flat`` chooses the flat loop or the nested one (the target's own, :data:`FLAT`, when None):
    the same bits."""
    n = state.shape[1]
    outputs = (np.empty((periods, n, 4)), np.empty((periods, n)), np.empty((periods, n), np.int64),
               np.empty((periods, n)), np.empty((periods, n)))
    name = "march_flat" if (FLAT[device] if flat is None else flat) else "march"
    args = (observe, state, failed, groups) + tables.arguments() + outputs
    # unobserved, the kernel writes NaN for the extremes: a GPU's need not be copied back
    _launch(device, name, args, n, (1, 2), 5, kept=None if observe else len(args) - 2)
    sections, sides, impacts, top, bottom = outputs
    if not observe and device != "cpu":  # read-only, untouched memory
        top = bottom = np.broadcast_to(np.nan, (periods, n))
    return {"sections": sections, "sides": sides.astype(np.int64), "impacts": impacts, "top": top, "bottom": bottom}


def separate(device: str, tables: Tables, state: np.ndarray, failed: np.ndarray, groups: np.ndarray,
             offset: np.ndarray, scale: np.ndarray, delta: np.ndarray, periods: int) -> dict:
    """Each trajectory of ``state`` beside a companion ``offset`` ((4, n), updated) away,
    renormalised to ``delta`` (m, (n,), distances weighted by ``scale`` (4, n)) after every period,
    for ``periods`` periods (:func:`.kernel_source.separate_one`). Returns host arrays (periods, n):
    ``logs`` (the log of each period's stretch), ``samples`` (``p`` at each section), ``impacts``,
    ``top`` and ``bottom``."""
    n = state.shape[1]
    outputs = (np.empty((periods, n)), np.empty((periods, n)), np.empty((periods, n), np.int64),
               np.empty((periods, n)), np.empty((periods, n)))
    args = (state, failed, groups, offset, np.ascontiguousarray(scale), np.ascontiguousarray(delta))
    _launch(device, "separate", args + tables.arguments() + outputs, n, (0, 1, 3), 5)
    logs, samples, impacts, top, bottom = outputs
    return {"logs": logs, "samples": samples, "impacts": impacts, "top": top, "bottom": bottom}


def _launch(device: str, name: str, args: tuple, n: int, updated: tuple, outputs: int,
            kept: int | None = None) -> None:
    """Run the driver ``name`` over ``n`` trajectories; on a GPU, copy the inputs there (the last
    ``outputs`` arguments are only allocated there: the kernel writes them whole) and the
    ``updated`` ones and the outputs back (those before the argument ``kept`` only, when given)."""
    compiled = target(device)[name]
    if n == 0:
        return
    if device == "cpu":
        compiled(*args)
        return
    from numba import cuda
    first_output = len(args) - outputs
    # the outputs are written whole by the kernel: allocated there, never copied in
    on_device = [a if not isinstance(a, np.ndarray) else cuda.device_array_like(a) if k >= first_output
                 else cuda.to_device(np.ascontiguousarray(a)) for k, a in enumerate(args)]
    compiled[(n + GPU_THREADS - 1) // GPU_THREADS, GPU_THREADS](*on_device)
    for k in list(updated) + list(range(first_output, len(args) if kept is None else kept)):
        on_device[k].copy_to_host(args[k])
