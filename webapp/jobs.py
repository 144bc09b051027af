"""Job queues: the interface the web layer uses, the embedded backend (worker pool + SQLite) and RQ on Redis.

Jobs never run in a request thread. DELETE semantics (both backends): a queued job is cancelled and removed;
a finished job (done, failed, cancelled) is removed with its files; a running job is marked 'cancelling' and
its worker stops at the next progress step, then removes it.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
import time
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from webapp.jobstore import (CANCELLED, CANCELLING, FAILED, FINISHED, QUEUED, RUNNING, Job, JobStore, RedisStore,
                             SQLiteStore)
from webapp.runner import run_job
from webapp.storage import Storage

log = logging.getLogger("facesvg.webapp")
MAX_ATTEMPTS = 2  # a job interrupted by a server stop is re-queued once, then marked failed


class JobQueue:
    """What the web layer needs: submit, look up, list, delete, clean up. Backends fill in the execution."""

    def __init__(self, store: JobStore, storage: Storage, preview_frames: int = 48) -> None:
        self.store = store
        self.storage = storage
        self.preview_frames = preview_frames

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

    def _enqueue(self, job_id: str) -> None:
        raise NotImplementedError

    def _dequeue(self, job_id: str) -> None:
        """Best effort: drop a cancelled job from the backend's queue (workers skip it anyway)."""


class EmbeddedQueue(JobQueue):
    """Worker pool inside the server (processes by default) and the SQLite job table in the instance folder.

    On start, jobs left 'running' by a server that died are re-queued (once) or marked failed; queued ones
    are resubmitted. Run one server process per instance folder (waitress is threaded; one process is right).
    """

    name = "embedded"

    def __init__(self, db_path: str | Path, storage: Storage, workers: int = 2, executor: str = "process",
                 preview_frames: int = 48) -> None:
        super().__init__(SQLiteStore(db_path), storage, preview_frames)
        self.workers = max(1, int(workers))
        self.kind = executor
        self._lock = threading.Lock()
        self._futures: dict[str, Future] = {}
        self._closed = False
        self._pool = self._new_pool()
        self.recovered = self.recover()

    def _new_pool(self) -> Executor:
        if self.kind == "thread":
            return ThreadPoolExecutor(self.workers, thread_name_prefix="facesvg-job")
        # spawn, not fork: the server has threads, and each worker needs its own clean EGL context
        return ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"))

    def recover(self) -> dict[str, list[str]]:
        """Re-queue or fail jobs a previous server left running; resubmit queued ones."""
        requeued, failed = [], []
        for job in self.store.with_state((RUNNING, CANCELLING)):
            if job.state == CANCELLING:
                self.store.remove(job.id)
                self.storage.delete(job.id)
            elif job.attempts < MAX_ATTEMPTS and self.store.transition(
                    job.id, (RUNNING,), state=QUEUED, stage="re-queued after a server restart", progress=0.0):
                requeued.append(job.id)
            elif self.store.transition(job.id, (RUNNING,), state=FAILED, stage="failed", finished=time.time(),
                                       message=f"the server stopped while this job was running "
                                               f"({job.attempts} attempts); submit it again."):
                failed.append(job.id)
        for job in self.store.with_state((QUEUED,)):
            self._enqueue(job.id)
        return {"requeued": requeued, "failed": failed}

    def _enqueue(self, job_id: str) -> None:
        with self._lock:
            if self._closed:
                return
            fut = self._pool.submit(run_job, job_id, self.store.url, str(self.storage.root), self.preview_frames)
            self._futures[job_id] = fut
        fut.add_done_callback(lambda f, j=job_id: self._finished(j, f))

    def _dequeue(self, job_id: str) -> None:
        fut = self._futures.get(job_id)
        if fut is not None:
            fut.cancel()

    def _finished(self, job_id: str, fut: Future) -> None:
        """A worker returned; if it crashed (not a conversion error, which run_job records), record that."""
        with self._lock:
            self._futures.pop(job_id, None)
        if fut.cancelled() or self._closed:  # a shutdown, not a crash: the job is re-queued on restart
            return
        exc = fut.exception()
        if exc is None:
            return
        log.error("worker for job %s crashed: %r", job_id, exc)
        self.store.transition(job_id, (RUNNING, QUEUED), state=FAILED, stage="failed", finished=time.time(),
                              message="the conversion process stopped unexpectedly (out of memory or a crash); "
                                      "try smaller options or another file.")
        if isinstance(exc, BrokenProcessPool):
            self._restart_pool()

    def _restart_pool(self) -> None:
        with self._lock:
            if self._closed:
                return
            old, self._pool = self._pool, self._new_pool()
            pending = list(self._futures)
            self._futures.clear()
        old.shutdown(wait=False, cancel_futures=True)
        for job_id in pending:
            job = self.store.get(job_id)
            if job is not None and job.state == QUEUED:
                self._enqueue(job_id)

    def close(self, wait: bool = True) -> None:
        """Stop the pool and close the table; without wait, running workers are killed (re-queued on restart)."""
        with self._lock:
            self._closed = True
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=wait, cancel_futures=True)
        for proc in processes if not wait else ():
            proc.terminate()
        super().close()


class RQQueue(JobQueue):
    """Jobs on an RQ queue in Redis, records in Redis, results in a storage folder every worker shares.

    Workers run `facesvg worker --queue redis://... --storage FOLDER` (or `rq worker facesvg`) on any machine.
    """

    name = "rq"

    def __init__(self, url: str, storage: Storage, queue_name: str = "facesvg", job_timeout: int = 3600,
                 preview_frames: int = 48) -> None:
        from redis import Redis
        from rq import Queue

        super().__init__(RedisStore(url, prefix=queue_name), storage, preview_frames)
        self.url = url
        self.job_timeout = job_timeout
        self.connection = Redis.from_url(url)
        self.queue = Queue(queue_name, connection=self.connection)

    def _enqueue(self, job_id: str) -> None:
        self.queue.enqueue(run_job, job_id, self.url, str(self.storage.root), self.preview_frames,
                           job_id=job_id, job_timeout=self.job_timeout, result_ttl=600, failure_ttl=86400)

    def _dequeue(self, job_id: str) -> None:
        from rq.job import Job as RQJob

        try:
            RQJob.fetch(job_id, connection=self.connection).cancel()
        except Exception:  # already taken, finished or expired: the worker's claim skips cancelled jobs anyway
            pass

    def get(self, job_id: str) -> Job | None:
        """The record; a job whose RQ worker died (RQ marks it failed) is recorded as failed."""
        job = self.store.get(job_id)
        if job is not None and job.state in (QUEUED, RUNNING, CANCELLING):
            from rq.exceptions import NoSuchJobError
            from rq.job import Job as RQJob

            try:
                status = RQJob.fetch(job_id, connection=self.connection).get_status(refresh=True)
            except NoSuchJobError:
                status = None
            if status is not None and str(getattr(status, "value", status)) in ("failed", "stopped", "canceled"):
                if self.store.transition(job_id, (QUEUED, RUNNING), state=FAILED, stage="failed",
                                         finished=time.time(),
                                         message="the worker running this job stopped (crash or timeout); "
                                                 "submit it again."):
                    job = self.store.get(job_id)
        return job

    def close(self, wait: bool = True) -> None:
        super().close()
        self.connection.close()


def make_queue(config: dict) -> JobQueue:
    """The backend the configuration names: FACESVG_QUEUE = 'embedded' (default) or redis://..."""
    storage = Storage(config["FACESVG_STORAGE"])
    url = config.get("FACESVG_QUEUE") or "embedded"
    previews = int(config.get("FACESVG_PREVIEW_FRAMES", 48))
    if url.startswith(("redis://", "rediss://", "unix://")):
        return RQQueue(url, storage, job_timeout=int(config.get("FACESVG_JOB_TIMEOUT", 3600)),
                       preview_frames=previews)
    if url != "embedded":
        raise ValueError(f"FACESVG_QUEUE must be 'embedded' or a redis:// URL, got {url!r}")
    return EmbeddedQueue(Path(config["FACESVG_DB"]), storage, workers=int(config.get("FACESVG_WORKERS", 2)),
                         executor=config.get("FACESVG_EXECUTOR", "process"), preview_frames=previews)
