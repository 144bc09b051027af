"""Compiled loops (numba, nogil) run over slices of their items on a few threads."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager

import numpy as np
from threadpoolctl import threadpool_limits

THREADS = max(1, min(4, os.cpu_count() or 1))


_pool: tuple[int, ThreadPoolExecutor] | None = None  # (pid that made it, pool): a forked child makes its own


def _helpers() -> ThreadPoolExecutor:
    """THREADS - 1 threads kept for the life of the process: a pool per call started ~260 threads a conversion
    of the capture-like face (0.2 s)."""
    global _pool
    if _pool is None or _pool[0] != os.getpid():  # a pool's threads do not survive fork
        _pool = (os.getpid(), ThreadPoolExecutor(THREADS - 1, thread_name_prefix="facesvg-kernel"))
    return _pool[1]


def threaded(kernel: Callable[..., None], n: int, *args) -> None:
    """kernel(*args, first, stop) for THREADS slices first..stop of range(n), the first on this thread; the
    kernel must release the GIL."""
    threads = max(1, min(THREADS, n))
    bounds = np.linspace(0, n, threads + 1).astype(np.int64).tolist()
    if threads == 1:
        kernel(*args, 0, n)
        return
    pool = _helpers()
    rest = [pool.submit(kernel, *args, bounds[i], bounds[i + 1]) for i in range(1, threads)]
    try:
        kernel(*args, bounds[0], bounds[1])
    finally:  # the others write into the same arrays: they finish before this returns or raises
        for f in rest:
            f.result()


def serial_blas() -> AbstractContextManager:
    """A context in which numpy's BLAS runs on one thread.

    The converter's products are many small ones (per-frame 3x3 solves, (T, n) @ (n, 9) fits, 2x2 maps) where
    OpenBLAS's threads spin more than they compute: on the capture-like face they cost 1.7 s of CPU of 14 for
    no wall time saved (2026-12-03)."""
    return threadpool_limits(1, user_api="blas")
