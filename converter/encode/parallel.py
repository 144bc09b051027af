"""Compiled loops (numba, nogil) run over slices of their items on a few threads."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

THREADS = max(1, min(4, os.cpu_count() or 1))


def threaded(kernel: Callable[..., None], n: int, *args) -> None:
    """kernel(*args, first, stop) for THREADS slices first..stop of range(n); the kernel must release the GIL."""
    threads = max(1, min(THREADS, n))
    bounds = np.linspace(0, n, threads + 1).astype(np.int64)
    if threads == 1:
        kernel(*args, 0, n)
        return
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda i: kernel(*args, bounds[i], bounds[i + 1]), range(threads)))
