"""Compiled loops (numba, nogil) run over slices of their items on a few threads."""

from __future__ import annotations

import itertools
import os
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import AbstractContextManager
from typing import TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

MAX_THREADS = 4  # the default's cap: past it the loops gain little and the per-thread buffers cost memory
ENV = "FACESVG_THREADS"


def thread_count(text: str) -> int:
    """A thread count written as text: a whole number >= 1, else ValueError."""
    if not text.strip().isdigit() or int(text) < 1:
        raise ValueError(f"expected a whole number >= 1, not {text!r}")
    return int(text)


def default_threads() -> int:
    """The kernels' thread count: FACESVG_THREADS when it is a thread_count, else the CPUs this process may run
    on (its affinity, which taskset and container CPU sets narrow), at most MAX_THREADS."""
    value = os.environ.get(ENV, "").strip()
    if value:
        try:
            return thread_count(value)
        except ValueError as exc:
            warnings.warn(f"{ENV}: {exc}: ignored", stacklevel=2)
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cpus))


THREADS = default_threads()
T = TypeVar("T")
PIECES = 4  # slices of a threaded loop per thread (with halves, the thread done first sat waiting on the ICT head)


def use_threads(n: int) -> None:
    """Run the kernels on n threads from now on (the CLI's --threads)."""
    global THREADS
    if n < 1:
        raise ValueError(f"threads must be >= 1, not {n}")
    THREADS = n


_pool: tuple[int, int, ThreadPoolExecutor] | None = None  # (pid that made it, helpers, pool): a forked child or a
# new thread count makes its own


def _helpers() -> ThreadPoolExecutor:
    """THREADS - 1 threads kept for the life of the process: a pool per call started hundreds of threads a
    conversion."""
    global _pool
    helpers = max(1, THREADS - 1)
    if _pool is None or _pool[:2] != (os.getpid(), helpers):  # a pool's threads do not survive fork
        if _pool is not None and _pool[0] == os.getpid():
            _pool[2].shutdown(wait=False)
        _pool = (os.getpid(), helpers, ThreadPoolExecutor(helpers, thread_name_prefix="facesvg-kernel"))
    return _pool[2]


def slices(n: int, per_thread: int = 1) -> list[tuple[int, int]]:
    """range(n) cut into up to THREADS x per_thread consecutive slices (first, stop), as even as can be."""
    bounds = np.linspace(0, n, max(1, min(THREADS * per_thread, n)) + 1).astype(np.int64).tolist()
    return list(zip(bounds[:-1], bounds[1:]))


def run(calls: list[Callable[[], T]]) -> list[T]:
    """Each call's result, in order: the first call on this thread, the others on the helpers, which must release
    the GIL to run alongside; returns (or raises the first call's error) only once every call has finished."""
    if len(calls) <= 1:
        return [c() for c in calls]
    pool = _helpers()
    rest = [pool.submit(c) for c in calls[1:]]
    try:
        first = calls[0]()
    finally:  # the others write into the same arrays: they all finish before this returns or raises
        wait(rest)
    return [first, *(f.result() for f in rest)]


def threaded(kernel: Callable[..., None], n: int, *args) -> None:
    """kernel(*args, first, stop) over range(n) on THREADS threads (this one and the helpers): cut into up to
    PIECES slices a thread, each thread taking the next slice left when it is done with one, so that a thread
    given the costlier items does not keep the others waiting. The kernel must release the GIL, and a slice's
    result must not depend on which thread runs it or on how range(n) is cut."""
    threads = max(1, min(THREADS, n))
    if threads == 1:
        kernel(*args, 0, n)
        return
    pieces = slices(n, PIECES)
    taken = itertools.count()  # next() on it is atomic under the GIL

    def worker() -> None:
        while (i := next(taken)) < len(pieces):
            kernel(*args, *pieces[i])

    run([worker] * threads)


def serial_blas() -> AbstractContextManager:
    """A context in which numpy's BLAS runs on one thread.

    The converter's products are many small ones (per-frame 3x3 solves, (T, n) @ (n, 9) fits, 2x2 maps) where
    OpenBLAS's threads spin more than they compute: on the capture-like face they cost CPU for no wall time
    saved."""
    return threadpool_limits(1, user_api="blas")
