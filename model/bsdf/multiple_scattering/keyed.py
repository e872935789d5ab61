"""Orders >= min_order towards many targets from keyed, branch-split shared-path walks.

The estimator behind lobe.walk_to_targets for compiled walkers (keyed_kernel): per-walk
scores summed in batches; the variances use every walk, the covariance of the targets' errors
is the correlation of the first CORRELATION_WALKS walks (its m^2 per walk products were most
of the cost) scaled by those standard errors.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from functools import cache

import numpy as np
from threadpoolctl import ThreadpoolController

from model.bsdf.multiple_scattering import keyed_kernel
from model.bsdf.multiple_scattering.nee_kernel import surface
from model.bsdf.multiple_scattering.walk import ROULETTE
from model.cluster import usable_cores

#: Least probability of either branch at a dielectric facet (walk_kernel.branch_share), for
#: forward walks and reverse ones from outside, and for reverse walks from inside
#: (keyed_walk_from_starts: their useful paths stay in at the first events; 0.15 gave 6-9 %
#: less error at the Walter fits' worst points than 0.25, 0.1 about the same).
SHARE, INSIDE_SHARE = 0.25, 0.15
#: Walks whose per-walk products estimate the targets' correlation (the variances use all).
CORRELATION_WALKS = 1 << 14
#: Walk-target scores held at once (walks per batch = this // targets, at least
#: MIN_BATCH_WALKS): 2 MB, so a batch's scores stay in cache between the kernel and the sums
#: (32 MB batches took 4x as long).
BATCH_SCORES = 1 << 18
MIN_BATCH_WALKS = 1 << 9
#: Most threads filling one batch (the kernels release the GIL; a walk's numbers depend only
#: on its key and index and the batches do not depend on the threads, so neither does the
#: result), and the fewest walks per thread. Fewer where numba's thread count for the calling
#: thread is lower (1 in a Dask task: model.cluster's thread policy).
THREADS = usable_cores()
THREAD_MIN_WALKS = 1 << 8


class _Sums:
    """Running sums over walks of the scores (m,), their squares and, for the first
    CORRELATION_WALKS walks, their products (m, m)."""

    def __init__(self, m: int, correlation: bool):
        self.n, self.total, self.squares = 0, np.zeros(m), np.zeros(m)
        self.products = np.zeros((m, m)) if correlation else None
        self.head_total, self.n_products = np.zeros(m), 0

    def add(self, value: np.ndarray) -> None:
        self.n += len(value)
        self.total += value.sum(axis=0)
        self.squares += np.einsum("ij,ij->j", value, value)
        if self.products is not None and self.n_products < CORRELATION_WALKS:
            part = value[:CORRELATION_WALKS - self.n_products]
            self.products += part.T @ part
            self.head_total += part.sum(axis=0)
            self.n_products += len(part)

    def mean_error(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean per target and its standard error."""
        mean = self.total / self.n
        var = np.maximum(self.squares / self.n - mean * mean, 0.0) / max(self.n - 1, 1)
        return mean, np.sqrt(var)

    def covariance(self, err: np.ndarray) -> np.ndarray:
        """Covariance of the mean: the first walks' correlation scaled by the standard errors."""
        head = self.head_total / self.n_products
        spread = self.products / self.n_products - np.outer(head, head)
        sd = np.sqrt(np.maximum(np.diag(spread), 0.0))
        seen = sd > np.finfo(np.float64).tiny  # 1 / sd finite (a subnormal sd is dark)
        scale = np.where(seen, 1.0 / np.where(seen, sd, 1.0), 0.0)
        # one side at a time: |spread_ij| <= sd_i sd_j, so neither product overflows where an
        # all but dark target's sd is ~1e-170 (the outer product of the scales did, to nan)
        correlation = spread * scale[:, None] * scale[None, :]
        correlation = np.clip(0.5 * (correlation + correlation.T), -1.0, 1.0)
        np.fill_diagonal(correlation, 1.0)
        return correlation * np.outer(err, err)


_POOL_LOCK = threading.Lock()


@cache
def _pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of `threads` walk threads (dropped in a forked child)."""
    return ThreadPoolExecutor(threads, thread_name_prefix="gonio-walks")


if hasattr(os, "register_at_fork"):  # POSIX; elsewhere nothing forks a child with the pool
    os.register_at_fork(after_in_child=_pool.cache_clear)


def _threads() -> int:
    """Threads for this call: THREADS, at most numba's thread count on the calling thread."""
    try:
        import numba
    except ImportError:  # pragma: no cover - without the [fast] extra nothing is compiled
        return 1
    return max(1, min(THREADS, numba.get_num_threads()))


def _fill(walk, first: int, value: np.ndarray) -> None:
    """walk(first, value), its rows split between up to _threads() threads."""
    threads = _threads()
    parts = min(threads, len(value) // THREAD_MIN_WALKS)
    if parts < 2:
        walk(first, value)
        return
    with _POOL_LOCK:
        pool = _pool(threads)
    edges = np.linspace(0, len(value), parts + 1).astype(int)
    for done in [pool.submit(walk, first + lo, value[lo:hi])
                 for lo, hi in zip(edges[:-1], edges[1:], strict=True)]:
        done.result()


@cache
def _blas() -> ThreadpoolController:
    """The process's BLAS thread pools (numpy's, loaded by now)."""
    return ThreadpoolController()


def _walk_in_batches(walk, m: int, walks: int, covariance: bool
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(mean, standard error, covariance or None) over `walks` walks of m scores each, walk(first,
    value) filling value (walks in this batch, m) from walk index first. BLAS runs on one thread
    meanwhile: its threads, spinning between the batches' products, took the walk threads' cores
    (a table node of the Walter fit: 1.9 CPU s with them, 0.13 without)."""
    sums = _Sums(m, covariance)
    batch = max(MIN_BATCH_WALKS, BATCH_SCORES // max(m, 1))
    with _blas().limit(limits=1, user_api="blas"):
        while sums.n < walks:
            value = np.zeros((min(batch, walks - sums.n), m))
            _fill(walk, sums.n, value)
            sums.add(value)
    mean, err = sums.mean_error()
    return mean, err, sums.covariance(err) if covariance else None


def keyed_walk_to_targets(walker, wi: np.ndarray, targets: np.ndarray, walks: int,
                          rng: np.random.Generator, min_order: int = 2, covariance: bool = True,
                          share: float = SHARE
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(mean, standard error, covariance of the mean or None) of orders >= min_order of
    f |cos o| from wi (3,) towards every target (m, 3) over `walks` keyed walks of a compiled
    Walker (nee_kernel.supports), the key drawn from rng."""
    key = np.uint64(int(rng.integers(0, 2**63)))
    targets = np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 3)
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    s = surface(walker.slopes, walker.micro)
    return _walk_in_batches(
        lambda first, value: keyed_kernel.walk_targets(s, wi, targets, key, first,
                                                       int(min_order), float(ROULETTE),
                                                       float(share), value),
        len(targets), walks, covariance)


def keyed_walk_from_starts(walker, starts: np.ndarray, target: np.ndarray, walks: int,
                           rng: np.random.Generator, min_order: int = 2,
                           covariance: bool = True, share: float | None = None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(mean, standard error, covariance of the mean or None) of orders >= min_order of
    f(start, target) |cos target| for every start (n, 3, all on one side of the surface)
    towards one target (3,), over `walks` keyed walks (rounded up to whole rounds of the
    starts), each shared by all of them (keyed_kernel.walk_from_starts): the reverse of
    keyed_walk_to_targets. share: the branch share, by default INSIDE_SHARE for starts inside
    a dielectric and SHARE for starts above it."""
    starts = np.ascontiguousarray(starts, dtype=np.float64).reshape(-1, 3)
    if len(np.unique(starts[:, 2] > 0.0)) != 1:
        raise ValueError("keyed_walk_from_starts: the starts must all be on one side")
    if min_order < 2:
        raise ValueError(f"keyed_walk_from_starts: min_order must be >= 2 (its first event is "
                         f"not scored), not {min_order}")
    key = np.uint64(int(rng.integers(0, 2**63)))
    target = np.ascontiguousarray(target, dtype=np.float64).reshape(3)
    s = surface(walker.slopes, walker.micro)
    if share is None:
        share = SHARE if starts[0, 2] > 0.0 else INSIDE_SHARE
    n = len(starts)
    return _walk_in_batches(
        lambda first, value: keyed_kernel.walk_from_starts(
            s, starts, target, key, first, int(min_order), float(ROULETTE), float(share),
            value),
        n, -(-walks // n) * n, covariance)
