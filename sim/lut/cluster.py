"""Where Dask work runs: in-process threads (no client), a fresh local cluster of N worker
processes, or an existing cluster by scheduler address. Bakes and sweeps share this."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None,
                connect_timeout_s: float = 10.0) -> Iterator:
    """Yield None (threaded scheduler in this process), or a distributed Client on a local
    cluster of `workers` single-threaded processes, or on the cluster at `scheduler`."""
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
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster, Client(cluster) as client:
        yield client


def describe(workers: int | None, scheduler: str | None) -> str:
    """The layout in words, for output and metadata."""
    if scheduler is not None:
        return f"Dask cluster at {scheduler}"
    if workers is not None:
        return f"local Dask cluster, {workers} worker process(es)"
    return "in-process (Dask threaded scheduler)"


def map_tasks(fn: Callable, arguments: Sequence[tuple], client=None,
              progress: bool = False) -> list:
    """[fn(*args) for args in arguments], each call one Dask task: the threaded scheduler in
    this process when client is None, else the distributed Client. Results keep their order."""
    if client is None:
        import dask
        from dask.diagnostics import ProgressBar

        tasks = [dask.delayed(fn, pure=True)(*args) for args in arguments]
        if not progress:
            return list(dask.compute(*tasks, scheduler="threads"))
        with ProgressBar(out=sys.stderr):
            return list(dask.compute(*tasks, scheduler="threads"))
    futures = client.map(fn, *zip(*arguments, strict=True), pure=True)
    if progress:
        from distributed import as_completed
        from tqdm import tqdm

        for _ in tqdm(as_completed(futures), total=len(futures), file=sys.stderr, desc="tasks"):
            pass
    return client.gather(futures)
