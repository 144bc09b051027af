"""The RQ backend records a queued job whose RQ job died before any work horse claimed it (its worker was killed
after taking it from the queue): failed with a clear message, on the first attempt and on a re-queued one."""

from __future__ import annotations

from webapp.jobs import RQQueue
from webapp.jobstore import FAILED, QUEUED, Job
from webapp.storage import Storage, new_job_id


def test_a_job_whose_rq_job_failed_unclaimed_is_recorded_failed_on_every_attempt(tmp_path, redis_url):
    from rq.job import Job as RQJob
    from rq.job import JobStatus

    queue = RQQueue(redis_url, Storage(tmp_path / "jobs"), queue_name="unclaimed")
    try:
        for attempts, rq_suffix in ((0, ""), (1, "-retry1"), (2, "-retry2")):
            job = Job(id=new_job_id(), attempts=attempts)
            queue.submit(job)
            assert queue.get(job.id).state == QUEUED  # its RQ job waits on the queue: nothing to record
            # What RQ's maintenance does to a job its dead worker had taken: fail it (no horse ever claimed it).
            RQJob.fetch(job.id + rq_suffix, connection=queue.connection).set_status(JobStatus.FAILED)
            got = queue.get(job.id)
            assert got.state == FAILED and "could not start" in got.message, (attempts, got)
    finally:
        queue.close()
