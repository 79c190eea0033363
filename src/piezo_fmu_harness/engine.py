"""The sweep engine's backends: where the points of a sweep run.

Each worker extracts nothing itself and instantiates the FMU once; every point then resets the
instance, sets its parameters and steps it (:meth:`piezo_fmu_harness.fmu.Instance.run_point`). Points
come back in the order they finish, as JSON-safe records.

- :class:`ProcessPool` (default): local worker processes, one per core. FMU instances in one
  process would share the GIL, so parallelism needs processes.
- :class:`DaskCluster`: a ``distributed`` cluster, given by its scheduler address or started
  locally. The FMU travels to the workers as bytes (scattered once), so remote workers need
  only this package and fmpy installed, not the file.
- :class:`InProcess`: one after another on one instance in this process (``--jobs 1``).

Besides sweep points, every backend runs *tasks* (:meth:`ProcessPool.run_tasks`): a task is
``(tag, function, args)``, run as ``function(instance, *args)`` on a worker's instance, where
``function`` is a module-level function (it travels by name) returning a JSON-safe result. A
task's result may call for more tasks (``follow``), submitted before the result is handed on, so
that dependent work, such as the next frequency of a frequency sweep, keeps the workers busy.
The optimiser's evaluations are tasks too (the ``workers`` map of
``scipy.optimize.differential_evolution``).
"""

from __future__ import annotations

import atexit
import concurrent.futures
import ctypes
import multiprocessing
import os
import shutil
import signal
import tempfile
import threading
from collections import deque
from pathlib import Path
from typing import Callable, Iterable, Iterator, Optional

from .fmu import FmuModel, Instance


def default_jobs() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


# -- local process pool ----------------------------------------------------------------------------

_WORKER: Optional[Instance] = None


def _die_with_parent() -> None:
    """Linux: have the kernel end this worker when the sweep process dies (even by SIGKILL)."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:  # pragma: no cover - not Linux
        pass


def _init_worker(fmu_path: str, unzipdir: str, threads: int = 0) -> None:
    global _WORKER
    _die_with_parent()
    if threads and "NUMBA_NUM_THREADS" not in os.environ:
        # the compiled kernel's threads (numba, read when it is imported): this worker's share of
        # the cores, so that the workers' threads together do not outnumber the cores
        os.environ["NUMBA_NUM_THREADS"] = str(threads)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    _WORKER = Instance(FmuModel(fmu_path), unzipdir, instance_name=f"worker{os.getpid()}")


def _run_chunk_in_worker(items: list[tuple]) -> list[dict]:
    """Several ``(index, values, stop_time, step)`` points in one task: one round trip for all."""
    return [_WORKER.run_point(*item) for item in items]


def _run_task_in_worker(function: Callable, args: tuple):
    return function(_WORKER, *args)


#: A task: ``(tag, function, args)``, run as ``function(instance, *args)``.
Task = tuple
#: What follows a finished task: ``follow(tag, result)`` returns the tasks it calls for.
Follow = Optional[Callable[[object, object], Iterable[Task]]]


def _chunks(items: list, jobs: int) -> list[list]:
    """``items`` in tasks of a few points: enough tasks to keep every worker busy to the end
    (about 16 per worker), few enough that a task's round trip is small beside its work."""
    size = max(1, min(8, len(items) // (16 * max(1, jobs))))
    return [items[i:i + size] for i in range(0, len(items), size)]


class InProcess:
    """Points run one after another on one instance in this process (``--jobs 1``)."""

    description = "this process"

    def __init__(self, instance: Instance):
        self.instance = instance

    def run(self, todo: Iterable[tuple]) -> Iterator[tuple]:
        for tag, index, values, stop_time, step in todo:
            yield tag, self.instance.run_point(index, values, stop_time, step)

    def run_tasks(self, tasks: Iterable[Task], follow: Follow = None) -> Iterator[tuple]:
        """Run tasks in order, and the tasks their results call for; yield ``(tag, result)``."""
        queue = deque(tasks)
        while queue:
            tag, function, args = queue.popleft()
            result = function(self.instance, *args)
            if follow is not None:
                queue.extend(follow(tag, result))
            yield tag, result

    def close(self, cancel: bool = False) -> None:
        pass


class ProcessPool:
    """Points run in ``jobs`` local processes, each with its own FMU instance.

    A worker that dies (killed, out of memory) breaks the pool and loses the points in flight;
    the pool is then started anew and those points run again, so each point is still recorded
    exactly once. After :attr:`MAX_RESTARTS` such breaks the sweep stops (``--resume`` goes on).
    """

    #: Pools started anew after a worker died, before the sweep gives up.
    MAX_RESTARTS = 3

    def __init__(self, model: FmuModel, unzipdir: str, jobs: int):
        self.jobs = jobs
        self.description = f"process pool, {jobs} worker{'s' if jobs != 1 else ''}"
        self._pool_arguments = dict(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                    initializer=_init_worker,
                                    initargs=(str(model.path), unzipdir, max(1, default_jobs() // jobs)))
        self._executor = concurrent.futures.ProcessPoolExecutor(**self._pool_arguments)
        self.restarts = 0

    def run(self, todo: Iterable[tuple]) -> Iterator[tuple]:
        """Run ``(tag, index, values, stop_time, step)`` items; yield ``(tag, record)`` as each
        point finishes, each exactly once, across worker deaths."""
        remaining = {(item[0], item[1]): item for item in todo}
        while remaining:
            futures = {}
            for chunk in _chunks(list(remaining), self.jobs):
                items = [remaining[key][1:] for key in chunk]
                futures[self._executor.submit(_run_chunk_in_worker, items)] = chunk
            try:
                for future in concurrent.futures.as_completed(futures):
                    yield from self._finished(future.result(), futures[future], remaining)
            except concurrent.futures.process.BrokenProcessPool:
                if self.restarts >= self.MAX_RESTARTS:
                    raise
                self.restarts += 1
                # Tasks that finished before the break are kept; the rest run in a new pool.
                for future, chunk in futures.items():
                    if chunk[0] in remaining and future.done() and not future.cancelled() \
                            and future.exception() is None:
                        yield from self._finished(future.result(), chunk, remaining)
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = concurrent.futures.ProcessPoolExecutor(**self._pool_arguments)

    def run_tasks(self, tasks: Iterable[Task], follow: Follow = None) -> Iterator[tuple]:
        """Run tasks, and the tasks their results call for (``follow``, submitted before the
        result is yielded); yield ``(tag, result)`` as each finishes, each exactly once, across
        worker deaths (as :meth:`run`)."""
        pending: dict = {}

        def submit(task: Task) -> None:
            pending[self._executor.submit(_run_task_in_worker, task[1], task[2])] = task

        for task in tasks:
            submit(task)
        while pending:
            done, _ = concurrent.futures.wait(pending, return_when=concurrent.futures.FIRST_COMPLETED)
            lost = []
            for future in done:
                task = pending.pop(future)
                if isinstance(future.exception(), concurrent.futures.process.BrokenProcessPool):
                    lost.append(task)
                    continue
                result = future.result()
                if follow is not None:
                    for more in follow(task[0], result):
                        submit(more)
                yield task[0], result
            if lost:
                if self.restarts >= self.MAX_RESTARTS:
                    raise concurrent.futures.process.BrokenProcessPool("worker processes died repeatedly")
                self.restarts += 1
                # Every task in flight is lost with the pool: run them again in a new one.
                lost += list(pending.values())
                pending.clear()
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = concurrent.futures.ProcessPoolExecutor(**self._pool_arguments)
                for task in lost:
                    submit(task)

    @staticmethod
    def _finished(records: list[dict], chunk: list[tuple], remaining: dict) -> Iterator[tuple]:
        for key, record in zip(chunk, records):
            del remaining[key]
            yield key[0], record

    def close(self, cancel: bool = False) -> None:
        if cancel:
            # Interrupted: drop queued points and end the workers now (a point in flight is
            # simply not recorded; --resume runs it again).
            processes = list(getattr(self._executor, "_processes", {}).values())
            self._executor.shutdown(wait=False, cancel_futures=True)
            for process in processes:
                if process.is_alive():
                    process.kill()
        else:
            self._executor.shutdown(wait=True)


# -- dask.distributed ------------------------------------------------------------------------------

_DASK_INSTANCES = threading.local()


def _dask_instance(fmu_bytes: bytes, guid: str) -> Instance:
    """This worker thread's FMU instance for the FMU with ``guid``, made on first use."""
    cache = getattr(_DASK_INSTANCES, "by_guid", None)
    if cache is None:
        cache = _DASK_INSTANCES.by_guid = {}
    if guid not in cache:
        folder = Path(tempfile.mkdtemp(prefix="piezo_fmu_worker_"))
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
        path = folder / "PiezoImpactDamper.fmu"
        path.write_bytes(fmu_bytes)
        model = FmuModel(path)
        unzipdir = model.extract()
        atexit.register(shutil.rmtree, unzipdir, ignore_errors=True)
        cache[guid] = Instance(model, unzipdir, instance_name=f"dask{os.getpid()}")
    return cache[guid]


def _run_on_dask(fmu_bytes: bytes, guid: str, index: int, values: dict, stop_time: float, step: float) -> dict:
    return _dask_instance(fmu_bytes, guid).run_point(index, values, stop_time, step)


def _task_on_dask(fmu_bytes: bytes, guid: str, function: Callable, args: tuple):
    return function(_dask_instance(fmu_bytes, guid), *args)


class DaskCluster:
    """Points run on a ``distributed`` cluster: ``scheduler`` is its address, or ``None`` to
    start a local cluster of ``jobs`` single-threaded worker processes."""

    def __init__(self, model: FmuModel, scheduler: Optional[str], jobs: int):
        import logging

        from distributed import Client, LocalCluster

        self._cluster = None
        if scheduler is None:
            self._cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=logging.ERROR)
            self._client = Client(self._cluster)
            self.description = f"dask local cluster, {jobs} worker{'s' if jobs != 1 else ''}"
        else:
            self._client = Client(scheduler, timeout="30s")
            workers = len(self._client.scheduler_info().get("workers", {}))
            self.description = f"dask scheduler {scheduler}, {workers} workers"
        self._guid = model.guid
        self._fmu = self._client.scatter(model.path.read_bytes(), broadcast=True)
        self._futures = []

    def run(self, todo: Iterable[tuple]) -> Iterator[tuple]:
        """Run ``(tag, index, values, stop_time, step)`` items; yield ``(tag, record)`` as each
        point finishes."""
        from distributed import as_completed

        tags = {}
        for tag, index, values, stop_time, step in todo:
            future = self._client.submit(_run_on_dask, self._fmu, self._guid, index, values,
                                         stop_time, step, pure=False)
            tags[future.key] = tag
            self._futures.append(future)
        for future in as_completed(self._futures):
            yield tags[future.key], future.result()

    def run_tasks(self, tasks: Iterable[Task], follow: Follow = None) -> Iterator[tuple]:
        """Run tasks, and the tasks their results call for; yield ``(tag, result)`` as each
        finishes."""
        from distributed import as_completed

        tags = {}

        def submit(task: Task):
            future = self._client.submit(_task_on_dask, self._fmu, self._guid, task[1], task[2], pure=False)
            tags[future.key] = task[0]
            self._futures.append(future)
            return future

        running = as_completed([submit(task) for task in tasks])
        for future in running:
            result = future.result()
            if follow is not None:
                for more in follow(tags[future.key], result):
                    running.add(submit(more))
            yield tags[future.key], result

    def close(self, cancel: bool = False) -> None:
        if cancel and self._futures:
            self._client.cancel(self._futures)
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()
