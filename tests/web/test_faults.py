"""Fault injection: SIGKILL the server, a worker, or both at random points of 20 jobs; every job must end done
exactly once with a valid SVG, or failed with a clear message; none deleted, duplicated or stuck.

Real `facesvg serve` / `facesvg worker` processes on loopback, 6 s leases, bounded waits. Part of `make test`
(marked slow; see the report for its duration).
"""

from __future__ import annotations

import time

import pytest

from web.faults import RQWorker, Serve, embedded_run, rq_run, second_serve_run, settle_all, submit

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("seed", [1, 2])
def test_kills_on_the_embedded_backend_lose_nothing(tmp_path, seed):
    out = embedded_run(tmp_path / "inst", seed, n=20, kills=2)
    assert out.jobs == 20 and sum(out.kills.values()) == 2
    assert (out.lost, out.duplicated, out.deleted, out.invalid) == (0, 0, 0, 0), out
    assert out.unlogged <= 2 * sum(out.kills.values()), out  # at most a job per killed worker (2 per server kill)
    assert out.done + out.failed == 20
    assert out.done >= 18, out  # a job fails only if its worker was killed on both attempts
    for message in out.messages:
        assert "stopped unexpectedly" in message and "--" not in message


def test_second_serve_on_the_same_folder_exits_and_touches_nothing(tmp_path):
    out, code, err, before, after = second_serve_run(tmp_path / "inst", n=20)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "already serving" in lines[0], err
    # The live server's running jobs kept their owner and attempt count: the second one re-queued nothing.
    for job_id, (state, owner, attempts) in before.items():
        if state == "running":
            assert after[job_id][1:] == (owner, attempts) or after[job_id][0] in ("done", "failed")
    assert (out.done, out.failed, out.lost, out.duplicated, out.deleted, out.invalid, out.unlogged) == \
        (20, 0, 0, 0, 0, 0, 0), out


@pytest.mark.parametrize("seed", [1])
def test_killed_rq_workers_lose_nothing(tmp_path, redis_url, seed):
    out = rq_run(tmp_path / "inst", redis_url, seed, n=20, kills=2)
    logs = f"{out}; the RQ workers' logs: {tmp_path}/rq-worker-*.log"
    assert out.jobs == 20 and sum(out.kills.values()) == 2
    assert (out.lost, out.duplicated, out.deleted, out.invalid) == (0, 0, 0, 0), logs
    assert out.unlogged <= 2 * sum(out.kills.values()), logs
    assert out.done >= 18, logs


def test_rq_job_its_dead_worker_took_but_never_started_is_recovered_while_workers_idle(tmp_path, redis_url):
    """A worker killed after taking a job off the queue but before its horse claimed it leaves the job in RQ's
    intermediate queue; only RQ's maintenance, run by a live worker, fails it (after a minute there), and the
    server then re-queues it. An idle worker waited worker_ttl - 15 = 405 s between maintenance runs, so such a
    job sat queued for ~7 minutes once the queue had drained (a CI run lost one at the 420 s deadline)."""
    import redis
    from rq import Queue

    redis_url = redis_url.rsplit("/", 1)[0] + "/7"  # a database of its own: no other test's worker takes the job
    conn = redis.Redis.from_url(redis_url)
    conn.flushdb()
    server = Serve(tmp_path / "inst", queue=redis_url).wait_up()
    worker = None
    try:
        [job_id] = submit(server.url, 1, tag="abandoned-")
        queue = Queue("facesvg", connection=conn)
        taken = Queue.dequeue_any([queue], None, connection=conn)  # the dead worker's take, and nothing after it
        assert taken is not None and taken[0].id == job_id
        worker = RQWorker(redis_url, tmp_path / "rq-worker.log", env={"FACESVG_RQ_MAINTENANCE_SECONDS": "2"})
        # Its first maintenance (at start) marks the job first seen; once it idles, the mark is aged past RQ's
        # minute, so the next maintenance run fails the job.
        mark = queue.intermediate_queue.get_first_seen_key(job_id)
        end = time.monotonic() + 120
        while not conn.exists(mark) and time.monotonic() < end:
            time.sleep(0.1)
        assert conn.exists(mark), f"the worker ran no maintenance; its log: {tmp_path}/rq-worker.log"
        time.sleep(1)  # into its wait for work
        conn.set(mark, time.time() - 120, keepttl=True)
        t0 = time.monotonic()
        states = settle_all(lambda: server.url, [job_id], 60)
        assert states[job_id] and states[job_id]["state"] == "done", (states, f"{tmp_path}/rq-worker.log")
        assert time.monotonic() - t0 < 60
    finally:
        if worker:
            worker.stop()
        server.stop()
