"""Where a job stands: its place in the queue and an estimate of when it will be done."""

from __future__ import annotations

import time

from converter.options import seconds_left, seconds_left_since
from webapp.jobstore import DONE, QUEUED, RUNNING, Job

DEFAULT_SECONDS = 20.0  # a job's duration before any has finished on this server
MIN_BASIS_SECONDS = 1.5  # progress extrapolated over less time than this is noise: the ETA says "estimating"


def typical_duration(jobs: list[Job]) -> float:
    """The median run time of recent finished jobs (seconds), or a default before there are any."""
    took = sorted(j.finished - j.started for j in jobs if j.state == DONE and j.started and j.finished)
    return took[len(took) // 2] if took else DEFAULT_SECONDS


def measured(job: Job, now: float | None = None) -> float | None:
    """Seconds a running job still needs, from the progress the converter reported since it had read the input
    (before that from the start); None until there is a basis (a few percent over MIN_BASIS_SECONDS)."""
    now = time.time() if now is None else now
    elapsed = max(now - (job.started or now), 0.0)
    origin = job.progress_origin
    if origin:
        t0 = float(origin["time"])
        if now - t0 < MIN_BASIS_SECONDS:
            return None
        return seconds_left_since((t0, float(origin["progress"])), job.progress, now)
    if elapsed < MIN_BASIS_SECONDS:
        return None
    return seconds_left(elapsed, job.progress)


def remaining(job: Job, typical: float, now: float | None = None) -> float:
    """measured(), or the typical duration less the time spent (for queue arithmetic, never shown as the job's)."""
    now = time.time() if now is None else now
    left = measured(job, now)
    return left if left is not None else max(typical - max(now - (job.started or now), 0.0), 1.0)


def standing(queue, job: Job) -> dict:
    """{'queue_position': 1-based place among queued jobs or None, 'eta_seconds': estimate or None,
    'estimating': True while an active job's ETA has no basis yet (the page says "estimating…")}."""
    if job.state not in (QUEUED, RUNNING):
        return {"queue_position": None, "eta_seconds": None, "estimating": False}
    recent = queue.recent(30)
    typical = typical_duration(recent)
    if job.state == RUNNING:
        left = measured(job)
        return {"queue_position": None, "eta_seconds": None if left is None else round(left, 1),
                "estimating": left is None}
    queued = queue.store.with_state((QUEUED,))
    position = next((i + 1 for i, j in enumerate(queued) if j.id == job.id), len(queued))
    running = sorted(remaining(j, typical) for j in queue.store.with_state((RUNNING,)))
    workers = max(int(getattr(queue, "workers", 1) or 1), 1)
    # Jobs ahead are shared among the workers; the first free worker is the one whose job ends soonest.
    first_free = running[0] if len(running) >= workers else 0.0
    rounds = (position - 1) // workers
    if not any(j.state == DONE and j.started and j.finished for j in recent):  # no job has finished here yet
        return {"queue_position": position, "eta_seconds": None, "estimating": True}
    return {"queue_position": position, "eta_seconds": round(first_free + (rounds + 1) * typical, 1),
            "estimating": False}
