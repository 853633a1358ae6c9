"""Where likelihood evaluations run: this process, a local process pool, or a Dask cluster.

emcee evaluates the walkers of each half-ensemble with ``pool.map(log_prob, positions)``; all
three pools take the same picklable :class:`~abs.sampling.posterior.RenderPosterior`, which
compiles its scene once per worker process (Dr.Jit state cannot be shared between processes, and
a worker thread must not use another thread's compiled scene).

- ``workers <= 1`` and no scheduler: evaluations in this process (``pool=None``).
- ``workers > 1``: a ``multiprocessing`` pool with the ``spawn`` start method (forking a process
  that has started LLVM threads can deadlock); each worker compiles the scene on its first call.
- ``scheduler="tcp://host:8786"``: a ``dask.distributed.Client`` on that scheduler; start the
  workers with one thread each (``dask worker tcp://host:8786 --nthreads 1``), since Dr.Jit already
  uses every core of a machine for one render.
"""

from __future__ import annotations

import multiprocessing
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["DaskPool", "evaluation_pool"]


class DaskPool:
    """``map`` over a Dask cluster (the interface emcee expects of a pool)."""

    def __init__(self, client):
        self.client = client

    def map(self, function: Callable, items) -> list:
        futures = self.client.map(function, list(items), pure=False)
        return self.client.gather(futures)


@contextmanager
def evaluation_pool(workers: int = 1, scheduler: str | None = None) -> Iterator[object | None]:
    """A pool for emcee (or ``None`` for in-process evaluations), closed on exit.

    Parameters
    ----------
    workers : int
        Local worker processes (ignored with a scheduler).
    scheduler : str, optional
        Dask scheduler address (``tcp://host:port``), or a ``dask.distributed.Client``.
    """
    if scheduler is not None:
        from dask.distributed import Client

        client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
        try:
            yield DaskPool(client)
        finally:
            if client is not scheduler:
                client.close()
    elif workers > 1:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            yield pool
    else:
        yield None
