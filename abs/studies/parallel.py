"""Map a function over independent tasks: a local process pool, or a Dask cluster.

Results are yielded as they complete (in any order) together with their task, so the caller can
checkpoint each one at once. The function and tasks must be picklable (a module-level function
and plain dicts). Local workers are *spawned*, not forked: a forked child of a process that has
started Dr.Jit's thread pool can deadlock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

__all__ = ["map_tasks"]


def map_tasks(function: Callable[[Any], Any], tasks: Sequence[Any], workers: int = 1,
              scheduler: str | None = None) -> Iterator[tuple[Any, Any]]:
    """Yield ``(task, function(task))`` for every task as it completes.

    Parameters
    ----------
    function : callable
        Module-level function of one task.
    tasks : sequence
        Picklable tasks.
    workers : int
        Local worker processes; 1 runs in this process (no pickling, easiest to debug).
        Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``) or a ``dask.distributed.Client`` /
        ``LocalCluster`` object's address; tasks then run on its workers, which must be able to
        import abs and read the files the tasks name.
    """
    if not tasks:
        return
    if scheduler is not None:
        from dask.distributed import Client, as_completed

        with Client(scheduler) as client:
            futures = client.map(function, list(tasks), pure=False)
            owner = {f.key: t for f, t in zip(futures, tasks)}
            for future in as_completed(futures):
                yield owner[future.key], future.result()
        return
    if workers <= 1:
        for task in tasks:
            yield task, function(task)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures import as_completed as futures_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(function, task): task for task in tasks}
        for future in futures_completed(futures):
            yield futures[future], future.result()
