"""Where independent evaluations run: this process, local worker processes, or a Dask cluster.

One pool for every caller that maps a function over independent items: the sampler's walkers
(emcee calls ``pool.map(log_prob, positions)`` and needs the results in order) and a study's
tasks (:meth:`WorkerPool.as_completed` yields each result as it finishes, so the caller can
checkpoint it at once).

- ``workers <= 1`` and no scheduler: evaluations in this process, in order (no pickling, easiest
  to debug).
- ``workers > 1``: local worker processes started with ``spawn``: a forked child of a process
  that has started Dr.Jit's (LLVM's) thread pool can deadlock. Workers live as long as the pool,
  so a function that compiles a scene on its first call (:class:`abs.sampling.RenderPosterior`)
  compiles it once per worker.
- ``scheduler``: a ``dask.distributed`` scheduler address (``tcp://host:8786``) or a ``Client``;
  start its workers with one thread each (``dask worker tcp://host:8786 --nthreads 1``), since
  Dr.Jit already uses every core of a machine for one render, and let them import abs and read
  the files the items name.

Functions and items must be picklable (module-level functions, plain data) unless they run in
this process. Imports nothing from abs, so every layer may use it (docs/architecture.md).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import as_completed as futures_completed
from contextlib import contextmanager
from typing import Any

__all__ = ["WorkerPool", "worker_pool"]


class WorkerPool:
    """Evaluations in this process; the base of the local and Dask pools."""

    def map(self, function: Callable[[Any], Any], items: Iterable[Any]) -> list:
        """``[function(item) for item in items]``, in order (the interface emcee expects)."""
        return [function(item) for item in items]

    def as_completed(self, function: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """Yield ``(task, function(task))`` for every task as it completes (in any order)."""
        for task in tasks:
            yield task, function(task)


class _LocalPool(WorkerPool):
    def __init__(self, executor: ProcessPoolExecutor):
        self.executor = executor

    def map(self, function, items) -> list:
        return list(self.executor.map(function, items))

    def as_completed(self, function, tasks):
        futures = {self.executor.submit(function, task): task for task in tasks}
        for future in futures_completed(futures):
            yield futures[future], future.result()


class _DaskPool(WorkerPool):
    def __init__(self, client):
        self.client = client

    def map(self, function, items) -> list:
        # pure=False: equal items are still evaluated each (a log-density may be random).
        return self.client.gather(self.client.map(function, list(items), pure=False))

    def as_completed(self, function, tasks):
        from dask.distributed import as_completed

        tasks = list(tasks)
        if not tasks:
            return
        futures = self.client.map(function, tasks, pure=False)
        owner = {f.key: t for f, t in zip(futures, tasks)}
        for future in as_completed(futures):
            yield owner[future.key], future.result()


@contextmanager
def worker_pool(workers: int = 1, scheduler=None) -> Iterator[WorkerPool]:
    """A pool (see the module docstring), closed on exit.

    Parameters
    ----------
    workers : int
        Local worker processes; 1 evaluates in this process. Ignored with ``scheduler``.
    scheduler : str or dask.distributed.Client, optional
        Dask scheduler address (``tcp://host:port``), or a client (left open on exit).
    """
    if scheduler is not None:
        from dask.distributed import Client

        client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
        try:
            yield _DaskPool(client)
        finally:
            if client is not scheduler:
                client.close()
    elif workers > 1:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            yield _LocalPool(pool)
    else:
        yield WorkerPool()
