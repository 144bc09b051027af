"""parallel.threaded: every slice once, helpers kept across calls, a slow slice does not hold the other thread,
none left running when a slice raises, and a forked child gets helpers of its own (a pool's threads do not
survive fork)."""

import os
import select
import signal
import threading
import time

import numba
import numpy as np
import pytest

from converter.encode import parallel


@numba.njit(nogil=True)
def _square(x, out, first, stop):
    for i in range(first, stop):
        out[i] = x[i] * x[i]


def _fill(out, tid, first, stop):
    out[first:stop] += 1
    tid[first:stop] = threading.get_ident()


@pytest.fixture
def two(monkeypatch):
    monkeypatch.setattr(parallel, "THREADS", 2)


def test_every_item_once_and_one_helper_kept_across_calls(two):
    out, tid = np.zeros(101, np.int64), np.zeros(101, np.int64)
    parallel.threaded(_fill, 101, out, tid)
    assert (out == 1).all()
    pool = parallel._pool
    parallel.threaded(_fill, 101, out, tid)
    assert (out == 2).all() and parallel._pool is pool  # the same helper: no thread started per call
    x = np.arange(1000, dtype=np.float64)
    sq = np.empty_like(x)
    parallel.threaded(_square, len(x), x, sq)
    assert np.array_equal(sq, x * x)


def test_a_slow_slice_does_not_keep_the_other_thread_waiting(two):
    # The first slice of 2 x PIECES takes 0.5 s: the thread that took it does nothing else, the other takes every
    # other slice (halves would have given one thread the slow slice and a half's worth more).
    n = 16 * parallel.PIECES
    out, tid = np.zeros(n, np.int64), np.zeros(n, np.int64)
    first_stop = n // (2 * parallel.PIECES)

    def kernel(out, tid, first, stop):
        if first == 0:
            time.sleep(0.5)
        _fill(out, tid, first, stop)

    parallel.threaded(kernel, n, out, tid)
    assert (out == 1).all()
    slow = set(tid[:first_stop].tolist())
    assert len(slow) == 1 and not slow & set(tid[first_stop:].tolist())


def test_a_slice_that_raises_returns_only_after_the_others_finished(two):
    done = []

    def kernel(first, stop):
        if first == 0:
            raise ValueError("slice 0")
        time.sleep(0.05)
        done.append(stop)

    with pytest.raises(ValueError, match="slice 0"):
        parallel.threaded(kernel, 40)
    assert sorted(done) == np.linspace(0, 40, 2 * parallel.PIECES + 1).astype(int)[2:].tolist()


def test_slices_cut_the_range_evenly_for_the_threads(two):
    assert parallel.slices(10) == [(0, 5), (5, 10)]
    assert parallel.slices(1) == [(0, 1)] and parallel.slices(0) == [(0, 0)]
    assert parallel.slices(10, 2) == [(0, 2), (2, 5), (5, 7), (7, 10)]  # per_thread slices a thread
    assert parallel.run([lambda: 1, lambda: 2, lambda: 3]) == [1, 2, 3]  # results in order, a call per helper


def test_a_forked_child_makes_helpers_of_its_own(two):
    out, tid = np.zeros(10, np.int64), np.zeros(10, np.int64)
    parallel.threaded(_fill, 10, out, tid)  # the parent's helper exists
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            child_out = np.zeros(10, np.int64)
            parallel.threaded(_fill, 10, child_out, np.zeros(10, np.int64))
            code = 0 if (child_out == 1).all() else 2
        finally:
            os.write(w, bytes([code]))
            os._exit(0)
    os.close(w)
    try:
        ready, _, _ = select.select([r], [], [], 30)
        if not ready:  # waiting on the parent's helper, which does not exist in the child
            os.kill(pid, signal.SIGKILL)
        assert ready and os.read(r, 1) == b"\x00"
    finally:
        os.close(r)
        os.waitpid(pid, 0)


def test_the_thread_count_comes_from_the_environment_else_the_cpus_this_process_may_use(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(16)), raising=False)
    monkeypatch.setenv(parallel.ENV, "3")
    assert parallel.default_threads() == 3
    monkeypatch.delenv(parallel.ENV)
    assert parallel.default_threads() == parallel.MAX_THREADS
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {5}, raising=False)  # taskset -c 5
    assert parallel.default_threads() == 1
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(parallel.ENV, bad)
        with pytest.warns(UserWarning, match=parallel.ENV):
            assert parallel.default_threads() == 1


def test_use_threads_runs_the_next_loop_on_that_many_threads(monkeypatch):
    monkeypatch.setattr(parallel, "THREADS", parallel.THREADS)  # restored after the test
    seen = set()
    lock = threading.Lock()
    all_three = threading.Barrier(3, timeout=30)  # broken (the loop raises) unless three threads take slices

    def kernel(first, stop):
        with lock:
            new = threading.get_ident() not in seen
            seen.add(threading.get_ident())
        if new and all_three is not None:
            all_three.wait()

    parallel.use_threads(2)
    parallel.threaded(_fill, 10, np.zeros(10), np.zeros(10, np.int64))  # a pool of one helper, kept
    parallel.use_threads(3)
    parallel.threaded(kernel, 60)
    assert len(seen) == 3
    seen.clear()
    all_three = None
    parallel.use_threads(1)
    parallel.threaded(kernel, 60)
    assert seen == {threading.get_ident()}
    with pytest.raises(ValueError):
        parallel.use_threads(0)
