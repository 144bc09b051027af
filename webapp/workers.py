"""The embedded backend's workers: long-lived processes (or threads) that claim jobs from the SQLite table.

Each worker loops: claim the oldest queued job with its owner id and a lease, run it with a heartbeat, repeat.
A supervisor thread in the server starts the workers (so Linux's parent-death signal, which follows the
thread that forked, lives as long as the server), replaces any that die, and settles only the job the dead
one held. It also re-queues jobs whose lease ran out (a holder that vanished without the supervisor seeing it).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
import time

from converter.isolated import die_with_parent
from webapp.jobstore import CANCELLING, RUNNING, JobStore, open_store
from webapp.lease import expired, new_owner, settle
from webapp.runner import execute
from webapp.storage import Storage
from webapp.warmup import warm_converter

log = logging.getLogger("facesvg.webapp")
POLL = 0.2  # seconds between looks at an empty queue


def worker_main(store_url: str, storage_root: str, owner: str, lease_seconds: float, preview_frames: int,
                parent_pid: int | None, stop) -> None:
    """A worker's life: claim, execute, repeat until stop.value is set (or, as a process, the server dies).

    stop is a lock-free shared flag: a worker killed mid-wait must not leave a lock or condition that would
    block the server (a multiprocessing.Event can deadlock its setter after a waiter died).
    """
    if parent_pid is not None:
        die_with_parent(parent_pid)
        warm_converter()  # before the first claim: the JIT's first call would starve the first job's heartbeat
    store = open_store(store_url)
    storage = Storage(storage_root)
    try:
        while not stop.value:
            if parent_pid is not None and os.getppid() != parent_pid:
                return
            try:
                job_id = store.claim_next(owner, lease_seconds)
            except Exception as exc:  # a locked or briefly unavailable table: try again shortly
                log.warning("worker %s could not claim: %r", owner, exc)
                job_id = None
            if job_id is None:
                time.sleep(POLL)
                continue
            execute(store, storage, job_id, owner, lease_seconds, preview_frames, parent_pid=parent_pid)
    finally:
        store.close()


class Slot:
    """One worker: its owner id and its process or thread."""

    def __init__(self, owner: str, runner) -> None:
        self.owner, self.runner = owner, runner

    def alive(self) -> bool:
        return self.runner.is_alive()

    @property
    def pid(self) -> int | None:
        return getattr(self.runner, "pid", None)


class WorkerPool:
    """N workers kept alive by a supervisor thread; a dead worker's job alone is retried or failed."""

    def __init__(self, store: JobStore, storage: Storage, workers: int, kind: str, lease_seconds: float,
                 retries: int, preview_frames: int) -> None:
        self.store, self.storage = store, storage
        self.n, self.kind = max(1, int(workers)), kind
        self.lease_seconds, self.retries, self.preview_frames = float(lease_seconds), int(retries), preview_frames
        self.ctx = multiprocessing.get_context("spawn")  # not fork: the server has threads; each needs its own EGL
        self.stop = self.ctx.RawValue("b", 0)
        self.slots: list[Slot] = []
        self.crashes = 0
        self._closing = threading.Event()  # no more respawning or settling
        self._exit = threading.Event()  # the supervisor may end (only after its workers are gone: PDEATHSIG)
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._supervise, name="facesvg-supervisor", daemon=True)
        self._thread.start()
        self._ready.wait(60)

    def _spawn(self) -> Slot:
        owner = new_owner("worker")
        args = (self.store.url, str(self.storage.root), owner, self.lease_seconds, self.preview_frames)
        if self.kind == "thread":
            runner = threading.Thread(target=worker_main, args=(*args, None, self.stop), daemon=True,
                                      name=f"facesvg-job-{owner[-8:]}")
        else:
            runner = self.ctx.Process(target=worker_main, args=(*args, os.getpid(), self.stop), daemon=True,
                                      name=f"facesvg-worker-{owner[-8:]}")
        runner.start()
        return Slot(owner, runner)

    def _supervise(self) -> None:
        self.slots = [self._spawn() for _ in range(self.n)]
        self._ready.set()
        while not self._exit.wait(0.25):
            if self._closing.is_set():
                continue
            for i, slot in enumerate(self.slots):
                if slot.alive() or self._closing.is_set():
                    continue
                self.crashes += 1
                log.error("worker %s (pid %s) died; settling its job", slot.owner, slot.pid)
                self.settle_owner(slot.owner, "its worker process died")
                self.slots[i] = self._spawn()
            self.reap()

    def settle_owner(self, owner: str, why: str) -> list[str]:
        """Settle every job the (dead) owner held; ids settled."""
        done = []
        for job in self.store.with_state((RUNNING, CANCELLING)):
            if job.owner == owner:
                if settle(self.store, self.storage, job.id, owner, self.retries, why):
                    done.append(job.id)
        return done

    def reap(self) -> list[str]:
        """Settle jobs whose lease expired and whose owner is not one of our live workers."""
        ours = {s.owner for s in self.slots if s.alive()}
        settled = []
        try:
            for job in expired(self.store):
                if job.owner in ours:
                    continue  # our own worker is alive and holds it (a late heartbeat); it renews soon
                if settle(self.store, self.storage, job.id, job.owner, self.retries, "its worker stopped answering"):
                    settled.append(job.id)
        except Exception as exc:  # keep supervising through a transient store error
            log.warning("reaper: %r", exc)
        return settled

    def pids(self) -> list[int]:
        """Process ids of the live worker processes (empty for threads)."""
        return [s.pid for s in self.slots if s.pid and s.alive()]

    def close(self, wait: bool = True) -> list[str]:
        """Stop the workers: wait lets running jobs finish; else they are killed and their leases released."""
        self._closing.set()
        self.stop.value = 1
        owners = [s.owner for s in self.slots]
        if self.kind == "process" and not wait:
            for slot in self.slots:
                slot.runner.kill()
        deadline = time.monotonic() + (600 if wait else 10)
        for slot in self.slots:
            slot.runner.join(max(deadline - time.monotonic(), 0.1))
        self._exit.set()
        self._thread.join(timeout=10)
        released = []
        if self.kind == "process":
            for slot, owner in zip(self.slots, owners):
                if slot.alive():
                    continue
                for job in self.store.with_state((RUNNING,)):
                    # Known dead: expire the lease now so the next start re-queues without waiting for it.
                    if job.owner == owner and self.store.transition(job.id, (RUNNING,), holder=owner, lease=0.0):
                        released.append(job.id)
        return released
