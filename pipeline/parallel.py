"""Where a run's independent tasks execute: in this process, a process pool, or a Dask cluster.

:class:`Executor` maps a function over task indices ``0 .. n-1`` and yields the results **in
task order as they arrive**, with at most ``ahead`` tasks submitted and not yet consumed (by
default twice the workers), so memory stays bounded whatever the number of tasks: the consumer
works on result ``i`` while later tasks run. The function receives a ``shared`` object (e.g. the
scene and its meshes) that is sent once per worker, not once per task.

* ``workers == 1`` and no scheduler: plain calls in this process (no pickling, no pool).
* ``workers > 1``: a :class:`concurrent.futures.ProcessPoolExecutor` whose processes start with
  ``spawn`` (a clean interpreter: forking a process whose open3d/numba thread pools are running
  can deadlock) and receive ``shared`` once, through the pool's initializer, which reads it
  from a file pickled once (:func:`_shared_handoff`: the workers start side by side).
* ``scheduler`` given: a :class:`distributed.Client` on that address; ``shared`` is scattered to
  every worker once (``broadcast=True``). The workers' allocator keeps freed arrays for reuse
  while the client is connected (:mod:`pipeline.worker_malloc`).

Results do not depend on where a task ran: every task is a pure function of ``(shared, index)``
(the simulation's random streams are functions of the pulse id, see
:mod:`pipeline.simulate.noise`), so 1 worker, N workers and a cluster give identical outputs.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import pickle
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from typing import Any

import numpy as np

__all__ = [
    "Executor",
    "choose_threading_layer",
    "default_workers",
    "kernel_threads",
    "stage_threads",
    "thread_map",
    "thread_map_rows",
]

#: What each pool process received through the initializer (``None`` in the parent).
_SHARED: Any = None


def default_workers() -> int:
    """Cores this process may run on (``os.sched_getaffinity``; ``os.cpu_count`` elsewhere)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def choose_threading_layer() -> None:
    """OpenMP for numba's parallel kernels, else numba's own workqueue; not TBB.

    The TBB that wheels bring along is often older than numba accepts: numba then warns on
    every run before it falls back. OpenMP also lets several Python threads launch kernels at
    once (the workqueue would abort). A user's ``NUMBA_THREADING_LAYER`` or
    ``NUMBA_THREADING_LAYER_PRIORITY`` wins. Call before the first parallel kernel runs.
    """
    import numba

    if not ({"NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY"} & set(os.environ)):
        numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]


@contextlib.contextmanager
def kernel_threads(n: int) -> Iterator[int]:
    """Run the compiled kernels' parallel loops on ``n`` threads (at most numba's pool) inside.

    Only kernels whose rows are independent run in parallel (the posterior's log-densities:
    :func:`pipeline.uncertainty.posterior_loop.run_steps`), so their values do not depend on
    ``n``. Yields the threads used; the previous count is restored on leaving. The count is
    numba's per calling thread; outside this block the kernels use every core (numba's
    default), so code that samples posteriors inside a process pool should set 1. Under the
    workqueue layer (no OpenMP on the machine) two Python threads must not run the kernels
    at once: numba aborts.
    """
    import numba

    choose_threading_layer()
    before = numba.get_num_threads()
    used = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(used)
    try:
        yield used
    finally:
        numba.set_num_threads(before)


#: Threads :func:`thread_map` may use (set by :func:`stage_threads`; 1 outside it).
_STAGE_THREADS = 1
_LOCAL = threading.local()


@contextlib.contextmanager
def stage_threads(n: int) -> Iterator[int]:
    """Let :func:`thread_map` run on ``n`` threads inside; yields the count.

    Outside such a block :func:`thread_map` calls its function in turn (a library caller
    gets no threads it did not ask for); ``bathy run`` opens one with its workers around the
    survey's stages.
    """
    global _STAGE_THREADS
    before, _STAGE_THREADS = _STAGE_THREADS, max(1, int(n))
    try:
        yield _STAGE_THREADS
    finally:
        _STAGE_THREADS = before


def thread_map(fn: Callable[[Any], Any], items: Any) -> list[Any]:
    """``[fn(x) for x in items]``, on the threads :func:`stage_threads` allows.

    For blocks of rows that numpy (and scipy's k-d tree) work on with the GIL released:
    their loops then run side by side. The results are in item order and, ``fn``'s calls
    being independent, the same for any number of threads. A call made inside one of the
    threads runs its items in turn (no nested pools). ``fn`` must not launch numba's
    ``parallel`` kernels (see :func:`kernel_threads`).
    """
    items = list(items)
    n = min(_STAGE_THREADS, len(items))
    if n <= 1 or getattr(_LOCAL, "inside", False):
        return [fn(x) for x in items]

    def call(x: Any) -> Any:
        _LOCAL.inside = True
        try:
            return fn(x)
        finally:
            _LOCAL.inside = False

    with ThreadPoolExecutor(max_workers=n) as pool:
        return list(pool.map(call, items))


def thread_map_rows(fn: Callable[[slice], tuple], n: int, block: int) -> tuple:
    """``fn`` over rows ``0 .. n - 1`` in blocks of ``block``, on :func:`thread_map`'s threads.

    ``fn(rows)`` returns a tuple of arrays whose first axis is the block's rows; each is
    concatenated over the blocks, in row order (one block, ``n <= block``: ``fn``'s own
    tuple; ``n = 0``: one empty block). For rows computed each on its own: the same values for
    any block size and thread count.
    """
    blocks = [slice(lo, min(lo + block, n)) for lo in range(0, max(n, 1), block)]
    parts = thread_map(fn, blocks)
    if len(parts) == 1:
        return parts[0]
    return tuple(np.concatenate(c) for c in zip(*parts, strict=True))


def _install(shared: Any) -> None:
    global _SHARED
    _SHARED = shared


def _install_from(path: str) -> None:
    global _SHARED
    with open(path, "rb") as f:
        _SHARED = pickle.load(f)


@contextlib.contextmanager
def _shared_handoff(shared: Any) -> Iterator[tuple[Callable[[Any], None], tuple[Any, ...]]]:
    """The pool's initializer and its arguments: ``shared`` pickled once, read by each worker.

    A spawned worker reads its initializer's arguments from a pipe only once it has imported
    the parent's main module (seconds), and the pool starts its workers one after the other,
    each start blocking on that pipe: with the scene's meshes (tens of MB) as the argument the
    N-th worker would begin N import times late. So ``shared`` is written once to an unnamed
    temporary file (``O_TMPFILE``: a killed run leaves nothing), and each worker gets only its
    ``/proc/<pid>/fd/<n>`` path, which it opens itself. Where there is no ``/proc`` the
    arguments go through the pipe as before.
    """
    proc = f"/proc/{os.getpid()}/fd"
    if not os.path.isdir(proc):
        yield _install, (shared,)
        return
    with tempfile.TemporaryFile() as f:
        pickle.dump(shared, f, protocol=pickle.HIGHEST_PROTOCOL)
        f.flush()
        yield _install_from, (f"{proc}/{f.fileno()}",)


def _pool_call(fn: Callable[..., Any], index: int, *data: Any) -> Any:
    return fn(_SHARED, index, *data)


def _dask_call(fn: Callable[..., Any], shared: Any, index: int, *data: Any) -> Any:
    return fn(shared, index, *data)


class Executor:
    """Runs tasks here, on a process pool or on a Dask cluster; a context manager.

    Parameters
    ----------
    workers : int or None
        Processes of the pool; ``None``: every core (:func:`default_workers`), or with a
        ``scheduler`` the cluster's threads. 1 without a scheduler: in this process.
    scheduler : str or None
        Address of a Dask distributed scheduler (e.g. ``tcp://10.0.0.5:8786``).
    ahead : int or None
        Tasks submitted and not yet consumed, at most; default ``2 * workers``.
    """

    def __init__(
        self, workers: int | None = None, scheduler: str | None = None, ahead: int | None = None
    ) -> None:
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1; got {workers}.")
        if ahead is not None and ahead < 1:
            raise ValueError(f"ahead must be >= 1; got {ahead}.")
        self.scheduler = scheduler
        self._client = None
        if scheduler is not None:
            from distributed import Client

            from pipeline.dask_malloc import GlibcThresholds

            self._client = Client(scheduler, set_as_default=False)
            # Dask's workers free large arrays to the system at once; ours reuse them
            # (pipeline.worker_malloc: the chunk loop's receiver at half the CPU)
            self._plugin = GlibcThresholds()
            self._client.register_plugin(self._plugin)
            if workers is None:
                workers = max(1, sum(self._client.nthreads().values()))
        self.workers = default_workers() if workers is None else int(workers)
        self.ahead = ahead if ahead is not None else 2 * self.workers
        self.map_wall_s = 0.0  # wall seconds inside timed map() calls, the consumer's work included
        # threads of this process's parallel kernels: the workers asked for, or with a
        # cluster (whose threads are elsewhere) this machine's cores
        self.local_threads = default_workers() if self._client else self.workers

    def describe(self) -> dict[str, Any]:
        """Where the tasks ran, JSON-ready (the manifest's ``execution``).

        ``{"workers", "scheduler", "engine", "map_wall_s", "local_threads"}``;
        ``map_wall_s``: wall seconds spent in :meth:`map` (the chunk loop's, its consumer's
        work included); ``local_threads``: threads of the kernels run in this process
        (:func:`kernel_threads`).
        """
        engine = "dask" if self._client else ("process_pool" if self.workers > 1 else "serial")
        return {
            "workers": self.workers,
            "scheduler": self.scheduler,
            "engine": engine,
            "map_wall_s": self.map_wall_s,
            "local_threads": self.local_threads,
        }

    def shares_file(self, path: str) -> bool:
        """Whether every worker opens the same file at ``path`` as this process.

        A pool's workers run on this machine and always do; a Dask cluster's do only on this
        machine (compared by device, inode and boot id, which ``/proc/<pid>/fd`` paths keep).
        Workers that join a cluster later are not asked.

        Parameters
        ----------
        path : str
            A path of this machine, e.g. ``/proc/<pid>/fd/<n>``.

        Returns
        -------
        bool
        """
        from pipeline.detection_reader import file_identity

        if self._client is None:
            return True
        seen = self._client.run(_file_identity, path)
        return bool(seen) and all(v == file_identity(path) for v in seen.values())

    def cluster_memory(self) -> list[tuple[str, int, float]]:
        """Each cluster worker's address, threads and the bytes it may still take.

        ``[]`` without a cluster. A worker's share is
        :data:`~pipeline.memory_budget.MEMORY_SHARE` of the smaller of its Dask
        ``memory_limit`` (0: none; Dask pauses a worker at 80 % of it) and its own machine's
        memory (:func:`~pipeline.memory_budget.machine_memory_bytes`, asked on the worker),
        less the memory it holds now. Workers that join later are not asked; one that leaves
        meanwhile counts as full.

        Returns
        -------
        list of (str, int, float)
            ``(address, threads, bytes)`` per worker.
        """
        if self._client is None:
            return []
        from pipeline.memory_budget import MEMORY_SHARE

        try:  # every worker (some versions list 5 unless asked)
            info = self._client.scheduler_info(n_workers=-1)["workers"]
        except TypeError:  # older: every worker by default
            info = self._client.scheduler_info()["workers"]
        machine = self._client.run(_machine_memory)
        out = []
        for address, w in info.items():
            limit = float(w.get("memory_limit") or 0.0) or math.inf
            share = MEMORY_SHARE * min(limit, float(machine.get(address, 0.0)))
            held = float(w.get("metrics", {}).get("memory", 0.0))
            out.append((address, int(w.get("nthreads", 1)), max(share - held, 0.0)))
        return out

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect from the cluster (pools live only while a :meth:`map` runs)."""
        if self._client is not None:
            with contextlib.suppress(Exception):  # a cluster already gone has nothing to undo
                self._client.unregister_worker_plugin(self._plugin.name)
            self._client.close()
            self._client = None

    def map(
        self,
        fn: Callable[[Any, int], Any],
        shared: Any,
        n_tasks: int,
        ahead: int | None = None,
        timed: bool = True,
        payload: Callable[[int], Any] | None = None,
        slots: list[str] | None = None,
    ) -> Iterator[Any]:
        """Yield ``fn(shared, i)`` for ``i = 0 .. n_tasks - 1``, in order, as they arrive.

        ``fn`` must be a module-level function (it is pickled by reference). Leaving the loop
        early (or an exception in a task) cancels the tasks not yet started. ``ahead``: tasks
        submitted and not yet consumed, at most (default the executor's); ``timed``: whether
        the wall seconds count in :attr:`map_wall_s` (the chunk loop's, in the manifest).

        ``payload``: data of task ``i`` alone, made here as the task is submitted (so at
        most ``ahead`` are alive) and sent with it: the task is then
        ``fn(shared, i, payload(i))``. For what the workers cannot read themselves (a
        cluster on other machines: a task's part of this process's files); on a cluster it
        is sent to a worker first (through the scheduler), not put in the task graph.

        ``slots`` (a cluster only): worker addresses, one per task that may run at once (a
        worker listed twice takes two); task ``i`` and its data go to ``slots[i % len]``
        and nowhere else, and at most ``len(slots)`` are pending (``ahead`` is ignored), so
        a task's slot is free when it is given out (the task ``len(slots)`` before it has
        been taken): no worker holds more at once than it is listed.
        """
        t0 = time.perf_counter()
        ahead = self.ahead if ahead is None else max(1, int(ahead))
        args = (lambda i: ()) if payload is None else (lambda i: (payload(i),))
        try:
            if self._client is not None:
                yield from self._map_dask(fn, shared, n_tasks, ahead, args, slots)
            elif self.workers == 1 or n_tasks <= 1:
                for i in range(n_tasks):
                    yield fn(shared, i, *args(i))
            else:
                yield from self._map_pool(fn, shared, n_tasks, ahead, args)
        finally:
            if timed:
                self.map_wall_s += time.perf_counter() - t0

    def _map_pool(self, fn, shared, n_tasks: int, ahead: int, args) -> Iterator[Any]:
        ctx = multiprocessing.get_context("spawn")
        # the file lives until the pool has shut down: every worker has read it by then
        with _shared_handoff(shared) as (initializer, initargs):
            pool = ProcessPoolExecutor(
                max_workers=min(self.workers, n_tasks),
                mp_context=ctx,
                initializer=initializer,
                initargs=initargs,
            )
            try:
                yield from _ordered(
                    lambda i: pool.submit(_pool_call, fn, i, *args(i)), n_tasks, ahead
                )
            finally:
                pool.shutdown(wait=True, cancel_futures=True)

    def _map_dask(self, fn, shared, n_tasks: int, ahead: int, args, slots) -> Iterator[Any]:
        client = self._client
        shared_f = client.scatter(shared, broadcast=True, hash=False)

        def submit(i: int):
            where = {} if not slots else {"workers": [slots[i % len(slots)]]}
            # a task's own data goes to a worker ahead of the task (the task then runs
            # where it lies), not into the graph the scheduler holds
            # (in a list: a tuple or dict given alone would be scattered item by item)
            data = [client.scatter([a], hash=False, **where)[0] for a in args(i)]
            if where:
                where["allow_other_workers"] = False
            return client.submit(_dask_call, fn, shared_f, i, *data, pure=False, **where)

        try:
            yield from _ordered(submit, n_tasks, len(slots) if slots else ahead)
        finally:
            client.cancel([shared_f])


def _machine_memory() -> float:
    """:func:`~pipeline.memory_budget.machine_memory_bytes` where this runs (a worker)."""
    from pipeline.memory_budget import machine_memory_bytes

    return machine_memory_bytes()


def _file_identity(path: str) -> tuple | None:
    """:func:`~pipeline.detection_reader.file_identity` of ``path`` here (None: no such file)."""
    from pipeline.detection_reader import file_identity

    try:
        return file_identity(path)
    except OSError:
        return None


def _ordered(submit: Callable[[int], Any], n_tasks: int, ahead: int) -> Iterator[Any]:
    """Results of ``submit(i).result()`` in order, never more than ``ahead`` pending."""
    pending: deque = deque()
    nxt = 0
    try:
        while nxt < n_tasks or pending:
            while nxt < n_tasks and len(pending) < ahead:
                pending.append(submit(nxt))
                nxt += 1
            fut = pending.popleft()
            yield fut.result()
            del fut  # the consumer holds the result; the future need not
    finally:
        for fut in pending:
            fut.cancel()
