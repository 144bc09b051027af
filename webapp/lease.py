"""Who owns what: the one-server-per-instance lock, worker owner ids and leases, dying with the parent.

A worker claims a job with its owner id and a lease (an expiry time) that a heartbeat thread renews. Every
later write of the worker is a compare-and-set on that owner, so a worker whose claim was lost (its lease ran
out and the job was re-queued) can only discard its result. Whoever finds an expired lease (the supervisor,
a reaper, recovery at start) settles the job once: re-queued while retries remain, else failed.
"""

from __future__ import annotations

import fcntl
import logging
import os
import socket
import threading
import time
import uuid
from pathlib import Path

from webapp.jobstore import CANCELLING, FAILED, QUEUED, RUNNING, JobStore
from webapp.storage import Storage

log = logging.getLogger("facesvg.webapp")
LOCK_NAME = "server.lock"


class InstanceBusy(RuntimeError):
    """Another live server holds this instance folder."""


class InstanceLock:
    """An exclusive flock on <instance>/server.lock, held for the server's life (the OS drops it on death)."""

    def __init__(self, folder: str | Path) -> None:
        self.path = Path(folder) / LOCK_NAME
        self.fd: int | None = None

    def acquire(self) -> InstanceLock:
        """Take the lock without waiting; InstanceBusy (naming the holder's pid) if another server has it."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise InstanceBusy(f"another facesvg server (pid {holder}) is already serving the instance folder "
                               f"{self.path.parent}; stop it first or use another --instance.") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self.fd = fd
        return self

    def release(self) -> None:
        """Drop the lock (closing the descriptor releases the flock)."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def new_owner(kind: str) -> str:
    """A fresh owner id naming host, process and a random part (unique per worker incarnation)."""
    return f"{kind}:{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


class Heartbeat:
    """Renews a job's lease every interval while the worker holds it; notices a lost claim or a dead parent."""

    def __init__(self, store: JobStore, job_id: str, owner: str, lease_seconds: float,
                 parent_pid: int | None = None) -> None:
        self.store, self.job_id, self.owner = store, job_id, owner
        self.lease_seconds = float(lease_seconds)
        self.parent_pid = parent_pid
        self.lost = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name=f"lease-{job_id[:8]}", daemon=True)

    def __enter__(self) -> Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def renew(self) -> bool:
        """Extend the lease now; False (and lost set) if this worker no longer holds the job."""
        ok = self.store.transition(self.job_id, (RUNNING, CANCELLING), holder=self.owner,
                                   lease=time.time() + self.lease_seconds)
        if not ok:
            self.lost.set()
        return ok

    def _beat(self) -> None:
        interval = max(self.lease_seconds / 4, 0.05)
        while not self._stop.wait(interval):
            if self.parent_pid is not None and os.getppid() != self.parent_pid:
                os._exit(1)  # the server died and the parent-death signal did not reach us: stop converting
            try:
                if not self.renew():
                    log.warning("job %s: lease renewal refused; %s lost its claim", self.job_id, self.owner)
                    return
            except Exception as exc:  # a busy or restarting store: try again next beat; the lease has slack
                log.warning("job %s: lease renewal failed (%r); retrying", self.job_id, exc)


def settle(store: JobStore, storage: Storage, job_id: str, owner: str, retries: int, why: str) -> str | None:
    """The holder of a job died: re-queue it while retries remain, else fail it; the outcome, or None if raced.

    A job being cancelled (DELETE while it ran) is marked cancelled, then removed with its files, as the DELETE
    asked.
    """
    job = store.get(job_id)
    if job is None or job.owner != owner or job.state not in (RUNNING, CANCELLING):
        return None
    if job.state == CANCELLING:
        if not store.transition(job_id, (CANCELLING,), holder=owner, state="cancelled", owner="",
                                finished=time.time()):
            return None
        store.remove(job_id)
        storage.delete(job_id)
        return "cancelled"
    if job.attempts <= retries:
        if store.transition(job_id, (RUNNING,), holder=owner, state=QUEUED, owner="", lease=0.0, progress=0.0,
                            progress_origin={}, stage=f"re-queued: {why}"):
            return "requeued"
        return None
    tries = "once" if job.attempts == 1 else f"{job.attempts} times"
    message = (f"the conversion stopped unexpectedly ({why}) {tries}; this input may need more memory than the "
               "server has: try a smaller size or triangle budget, or another file.")
    if store.transition(job_id, (RUNNING,), holder=owner, state=FAILED, stage="failed", owner="",
                        finished=time.time(), message=message):
        return "failed"
    return None


def expired(store: JobStore, now: float | None = None) -> list:
    """Running or cancelling jobs whose lease has run out (their holder is presumed dead)."""
    now = time.time() if now is None else now
    return [j for j in store.with_state((RUNNING, CANCELLING)) if (j.lease or 0.0) < now]
