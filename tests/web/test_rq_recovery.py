"""The RQ backend recovers a queued job whose RQ job died before any work horse claimed it (its worker was killed
after taking it from the queue): re-queued as a new RQ job while retries remain, then failed with a clear message."""

from __future__ import annotations

import threading

from webapp.jobs import RQQueue
from webapp.jobstore import FAILED, QUEUED, Job
from webapp.storage import Storage, new_job_id


def _fail_current_rq_job(queue: RQQueue, job_id: str) -> None:
    """What RQ's maintenance does to a job its dead worker had taken: fail it (no horse ever claimed it)."""
    from rq.job import Job as RQJob
    from rq.job import JobStatus

    rq_id = queue._rq_id(job_id, queue.store.get(job_id).attempts)
    RQJob.fetch(rq_id, connection=queue.connection).set_status(JobStatus.FAILED)


def _queued_rq_ids(queue: RQQueue) -> list[str]:
    return list(queue.queue.get_job_ids())


def test_a_job_whose_rq_job_failed_unclaimed_is_requeued_then_failed(tmp_path, redis_url):
    queue = RQQueue(redis_url, Storage(tmp_path / "jobs"), queue_name="unclaimed", retries=1)
    try:
        for attempts in (0, 1):  # a first submission, and a job re-queued once after its horse died
            job = Job(id=new_job_id(), attempts=attempts)
            queue.submit(job)
            assert queue.get(job.id).state == QUEUED  # its RQ job waits on the queue: nothing to record
            _fail_current_rq_job(queue, job.id)
            got = queue.get(job.id)
            if attempts < 1:  # a retry remains: re-queued as a new RQ job, the lost start counted
                assert got.state == QUEUED and got.attempts == attempts + 1, got
                assert "re-queued" in got.stage
                assert queue._rq_id(job.id, got.attempts) in _queued_rq_ids(queue)
                assert queue.get(job.id).attempts == attempts + 1  # asked again: nothing more happens
                _fail_current_rq_job(queue, job.id)  # the new RQ job's worker dies too: no retry left
                got = queue.get(job.id)
            assert got.state == FAILED and "could not start" in got.message, (attempts, got)
    finally:
        queue.close()


def test_concurrent_readers_requeue_an_unclaimed_job_once(tmp_path, redis_url):
    queue = RQQueue(redis_url, Storage(tmp_path / "jobs"), queue_name="unclaimed-race", retries=1)
    try:
        job = Job(id=new_job_id())
        queue.submit(job)
        _fail_current_rq_job(queue, job.id)
        stale = queue.store.get(job.id)
        readers = [threading.Thread(target=queue.get, args=(job.id,)) for _ in range(8)]
        for t in readers:
            t.start()
        for t in readers:
            t.join()
        got = queue.get(job.id)
        assert got.state == QUEUED and got.attempts == 1
        assert _queued_rq_ids(queue).count(queue._rq_id(job.id, 1)) == 1
        # A reader that read the record before the re-queue (and saw the first RQ job failed) comes late.
        queue._requeue_unclaimed(stale)
        assert queue.store.get(job.id).attempts == 1
        assert _queued_rq_ids(queue).count(queue._rq_id(job.id, 1)) == 1
    finally:
        queue.close()
