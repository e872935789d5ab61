"""Where Dask work runs: in-process threads (no client), a fresh local cluster of N worker
processes, or an existing cluster by scheduler address. Bakes and sweeps share this.

Thread policy: Dask owns the cores. Every task runs model.bsdf's numba kernels on one thread
(numba's thread count is per calling thread, and the kernels release the GIL), so the
in-process scheduler's one thread per core and a local cluster's workers x threads = cores
never stack a kernel thread pool on top of Dask's threads.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS reports one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def threads_per_worker(workers: int) -> int:
    """Dask threads per worker process of a local cluster: the cores shared out, at least 1."""
    return max(1, usable_cores() // workers)


def total_threads(client=None) -> int:
    """Dask threads that will run tasks: this process's cores, or all the cluster's threads."""
    if client is None:
        return usable_cores()
    return max(1, sum(client.nthreads().values()))


def run_with_one_kernel_thread(fn: Callable, *args):
    """fn(*args) with numba's parallel kernels on this thread limited to one thread (the
    previous count restored after), so Dask's threads are the only parallelism."""
    try:
        import numba
    except ImportError:  # pragma: no cover - without the [fast] extra there are no kernels
        return fn(*args)
    previous = numba.get_num_threads()
    if previous == 1:
        return fn(*args)
    numba.set_num_threads(1)
    try:
        return fn(*args)
    finally:
        numba.set_num_threads(previous)


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None,
                connect_timeout_s: float = 10.0) -> Iterator:
    """Yield None (threaded scheduler in this process), or a distributed Client on a local
    cluster of `workers` processes sharing the cores (threads_per_worker), or on the cluster
    at `scheduler`."""
    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    if workers is None and scheduler is None:
        yield None
        return
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=connect_timeout_s)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ValueError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from None
        with client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker(workers),
                      processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        yield client


def describe(workers: int | None, scheduler: str | None) -> str:
    """The layout in words, for output and metadata."""
    if scheduler is not None:
        return f"Dask cluster at {scheduler}"
    if workers is not None:
        return (f"local Dask cluster, {workers} worker process(es) x "
                f"{threads_per_worker(workers)} thread(s)")
    return f"in-process, Dask threaded scheduler, {usable_cores()} thread(s)"


def map_tasks(fn: Callable, arguments: Sequence[tuple], client=None,
              progress: bool = False) -> list:
    """[fn(*args) for args in arguments], each call one Dask task with one kernel thread
    (module docstring): the threaded scheduler in this process when client is None, else the
    distributed Client. Results keep their order."""
    if client is None:
        import dask
        from dask.diagnostics import ProgressBar

        tasks = [dask.delayed(run_with_one_kernel_thread, pure=True)(fn, *args)
                 for args in arguments]
        options = {"scheduler": "threads", "num_workers": usable_cores()}
        if not progress:
            return list(dask.compute(*tasks, **options))
        with ProgressBar(out=sys.stderr):
            return list(dask.compute(*tasks, **options))
    futures = client.map(run_with_one_kernel_thread, [fn] * len(arguments),
                         *zip(*arguments, strict=True), pure=True)
    if progress:
        from distributed import as_completed
        from tqdm import tqdm

        for _ in tqdm(as_completed(futures), total=len(futures), file=sys.stderr, desc="tasks"):
            pass
    return client.gather(futures)
