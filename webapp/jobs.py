"""Job queues: the interface the web layer uses, the embedded backend (worker pool + SQLite) and RQ on Redis.

Jobs never run in a request thread. DELETE semantics (both backends): a queued job is cancelled and removed;
a finished job (done, failed, cancelled) is removed with its files; a running job is marked 'cancelling' and
its worker stops at the next progress step, then removes it.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from webapp.jobstore import (
    CANCELLED,
    CANCELLING,
    FAILED,
    FINISHED,
    QUEUED,
    RUNNING,
    Job,
    JobStore,
    RedisStore,
    SQLiteStore,
)
from webapp.lease import expired, settle
from webapp.runner import run_job
from webapp.storage import Storage
from webapp.workers import WorkerPool

log = logging.getLogger("facesvg.webapp")
RETRIES = 1  # a job whose worker died (crash, kill, server stop) is re-queued this many times, then failed
LEASE_SECONDS = 30.0  # a worker's claim on a job lasts this long unless its heartbeat renews it


class JobQueue:
    """What the web layer needs: submit, look up, list, delete, clean up. Backends fill in the execution."""

    def __init__(self, store: JobStore, storage: Storage, preview_frames: int = 48) -> None:
        self.store = store
        self.storage = storage
        self.preview_frames = preview_frames
        self.instance_lock = None  # set by the app: released when the queue closes
        self.workers = 1

    name = "base"

    def submit(self, job: Job) -> None:
        """Record a new queued job (its files already stored) and hand it to a worker."""
        job.state, job.created = QUEUED, job.created or time.time()
        self.store.add(job)
        self._enqueue(job.id)

    def get(self, job_id: str) -> Job | None:
        """The job record, or None."""
        return self.store.get(job_id)

    def recent(self, limit: int = 50) -> list[Job]:
        """The newest jobs first."""
        return self.store.recent(limit)

    def delete(self, job_id: str) -> str | None:
        """Cancel or remove a job: 'deleted', 'cancelling' (running; stops soon), or None if unknown."""
        for _ in range(3):  # the state may change under us; retry the decision
            job = self.store.get(job_id)
            if job is None:
                return None
            if job.state == QUEUED and self.store.transition(job_id, (QUEUED,), state=CANCELLED):
                self._dequeue(job_id)
            elif job.state == RUNNING and self.store.transition(job_id, (RUNNING,), state=CANCELLING,
                                                                 stage="cancelling"):
                return "cancelling"
            elif job.state == CANCELLING:
                return "cancelling"
            elif job.state not in FINISHED:
                continue
            self.store.remove(job_id)
            self.storage.delete(job_id)
            return "deleted"
        return "cancelling"

    def cleanup(self, retention_seconds: float) -> list[str]:
        """Remove finished jobs older than the retention, and orphan folders with no record; returns ids."""
        cutoff = time.time() - retention_seconds
        gone = self.store.finished_before(cutoff)
        for job_id in gone:
            self.store.remove(job_id)
            self.storage.delete(job_id)
        for job_id in self.storage.job_ids():
            folder = self.storage.job_dir(job_id)
            if self.store.get(job_id) is None and folder.stat().st_mtime < cutoff:
                self.storage.delete(job_id)
                gone.append(job_id)
        return gone

    def close(self, wait: bool = True) -> None:
        """Stop accepting work and release resources (wait: let running jobs finish where the backend can)."""
        self.store.close()
        if self.instance_lock is not None:
            self.instance_lock.release()

    def _enqueue(self, job_id: str) -> None:
        raise NotImplementedError

    def _dequeue(self, job_id: str) -> None:
        """Best effort: drop a cancelled job from the backend's queue (workers skip it anyway)."""


class EmbeddedQueue(JobQueue):
    """Worker processes (or threads) beside the server, claiming jobs from the SQLite table in the instance folder.

    Start one server per instance folder (the instance lock enforces it). On start, jobs whose lease expired
    (their worker died with a previous server) are re-queued while retries remain, else failed; jobs still
    under a live lease are settled by the supervisor when it runs out.
    """

    name = "embedded"

    def __init__(self, db_path: str | Path, storage: Storage, workers: int = 2, executor: str = "process",
                 preview_frames: int = 48, lease_seconds: float = LEASE_SECONDS, retries: int = RETRIES) -> None:
        super().__init__(SQLiteStore(db_path), storage, preview_frames)
        self.workers = max(1, int(workers))
        self.kind = executor
        self.lease_seconds, self.retries = float(lease_seconds), int(retries)
        self.recovered = self.recover()
        self.pool = WorkerPool(self.store, storage, self.workers, executor, self.lease_seconds, self.retries,
                               preview_frames)

    def recover(self) -> dict[str, list[str]]:
        """Settle jobs a previous server left running whose lease has expired (queued ones just wait)."""
        requeued, failed = [], []
        for job in expired(self.store):
            outcome = settle(self.store, self.storage, job.id, job.owner, self.retries,
                             "the server stopped while it ran")
            if outcome == "requeued":
                requeued.append(job.id)
            elif outcome == "failed":
                failed.append(job.id)
        return {"requeued": requeued, "failed": failed}

    def _enqueue(self, job_id: str) -> None:
        """Nothing to hand over: workers claim queued jobs from the table."""

    def close(self, wait: bool = True) -> None:
        """Stop the workers and close the table; without wait, running workers are killed (re-queued on restart)."""
        if getattr(self, "pool", None) is not None:
            self.pool.close(wait=wait)
        super().close()


class RQQueue(JobQueue):
    """Jobs on an RQ queue in Redis, records in Redis, results in a storage folder every worker shares.

    Workers run `facesvg worker --queue redis://...` on any machine sharing the storage folder. RQ kills a work
    horse past the job timeout; our lease (renewed by the horse's heartbeat) tells the server's reaper which
    jobs lost their worker, and it re-queues each once (RETRIES) or fails it, as the embedded backend does.
    """

    name = "rq"

    def __init__(self, url: str, storage: Storage, queue_name: str = "facesvg", job_timeout: int = 3600,
                 preview_frames: int = 48, lease_seconds: float = LEASE_SECONDS, retries: int = RETRIES) -> None:
        from redis import Redis  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured
        from rq import Queue  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured

        super().__init__(RedisStore(url, prefix=queue_name), storage, preview_frames)
        self.url = url
        self.job_timeout = job_timeout
        self.lease_seconds, self.retries = float(lease_seconds), int(retries)
        self.connection = Redis.from_url(url)
        self.queue = Queue(queue_name, connection=self.connection)
        self._stop = threading.Event()
        self._reaper = threading.Thread(target=self._reap_loop, name="facesvg-rq-reaper", daemon=True)
        self._reaper.start()

    def _enqueue(self, job_id: str) -> None:
        job = self.store.get(job_id)
        rq_id = self._rq_id(job_id, job.attempts if job else 0)
        self.queue.enqueue(run_job, job_id, self.url, str(self.storage.root), self.preview_frames,
                           self.lease_seconds, job_id=rq_id, job_timeout=self.job_timeout, result_ttl=600,
                           failure_ttl=86400)

    @staticmethod
    def _rq_id(job_id: str, attempts: int) -> str:
        """The RQ job id of a job's next start after `attempts` claims: each re-queue is a new RQ job."""
        return f"{job_id}-retry{attempts}" if attempts else job_id

    def _dequeue(self, job_id: str) -> None:
        from rq.job import Job as RQJob  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured

        job = self.store.get(job_id)
        try:
            RQJob.fetch(self._rq_id(job_id, job.attempts if job else 0), connection=self.connection).cancel()
        except Exception:  # already taken, finished or expired: the worker's claim skips cancelled jobs anyway
            pass

    def reap(self) -> list[str]:
        """Settle jobs whose horse stopped renewing the lease; re-queued ones go back on the RQ queue."""
        settled = []
        for job in expired(self.store):
            outcome = settle(self.store, self.storage, job.id, job.owner, self.retries, "its worker stopped answering")
            if outcome == "requeued":
                self._enqueue(job.id)
            if outcome:
                settled.append(job.id)
        return settled

    def _reap_loop(self) -> None:
        while not self._stop.wait(max(self.lease_seconds / 4, 0.25)):
            try:
                self.reap()
            except Exception as exc:  # Redis restarting: keep trying
                log.warning("rq reaper: %r", exc)

    def get(self, job_id: str) -> Job | None:
        """The record. A queued job whose current RQ job failed before any horse claimed it (its worker died after
        taking it from the queue, and RQ's maintenance failed it) is re-queued while retries remain (the lost
        start counts as an attempt), else recorded as failed."""
        job = self.store.get(job_id)
        if job is not None and job.state == QUEUED and self._unclaimed_rq_failed(job):
            if job.attempts + 1 <= self.retries:  # as settle() counts: the lost start is an attempt
                self._requeue_unclaimed(job)
            else:
                self.store.transition(job_id, (QUEUED,), state=FAILED, stage="failed", finished=time.time(),
                                      message="the worker could not start this job; submit it again.")
            job = self.store.get(job_id)
        return job

    def _unclaimed_rq_failed(self, job: Job) -> bool:
        from rq.exceptions import NoSuchJobError  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured
        from rq.job import Job as RQJob  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured

        try:
            status = RQJob.fetch(self._rq_id(job.id, job.attempts), connection=self.connection).get_status(refresh=True)
        except NoSuchJobError:
            return False
        return str(getattr(status, "value", status)) in ("failed", "stopped")

    def _requeue_unclaimed(self, job: Job) -> None:
        # One reader wins: the conditional write takes the owner field this reader saw (empty, or the mark of the
        # last such re-queue) and leaves a mark naming the new attempt, so a reader holding an older copy of the
        # record cannot re-queue it again. A horse's claim overwrites the mark.
        if self.store.transition(job.id, (QUEUED,), holder=job.owner, owner=f"requeued:{job.attempts + 1}",
                                 attempts=job.attempts + 1, stage="re-queued: its worker stopped before starting it"):
            self._enqueue(job.id)

    def close(self, wait: bool = True) -> None:
        self._stop.set()
        self._reaper.join(timeout=5)
        super().close()
        self.connection.close()


def make_queue(config: dict) -> JobQueue:
    """The backend the configuration names: FACESVG_QUEUE = 'embedded' (default) or redis://..."""
    storage = Storage(config["FACESVG_STORAGE"])
    url = config.get("FACESVG_QUEUE") or "embedded"
    previews = int(config.get("FACESVG_PREVIEW_FRAMES", 48))
    lease = float(config.get("FACESVG_LEASE_SECONDS", LEASE_SECONDS))
    retries = int(config.get("FACESVG_RETRIES", RETRIES))
    if url.startswith(("redis://", "rediss://", "unix://")):
        return RQQueue(url, storage, job_timeout=int(config.get("FACESVG_JOB_TIMEOUT", 3600)),
                       preview_frames=previews, lease_seconds=lease, retries=retries)
    if url != "embedded":
        raise ValueError(f"FACESVG_QUEUE must be 'embedded' or a redis:// URL, got {url!r}")
    return EmbeddedQueue(Path(config["FACESVG_DB"]), storage, workers=int(config.get("FACESVG_WORKERS", 2)),
                         executor=config.get("FACESVG_EXECUTOR", "process"), preview_frames=previews,
                         lease_seconds=lease, retries=retries)
