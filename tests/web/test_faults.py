"""Fault injection: SIGKILL the server, a worker, or both at random points of 20 jobs; every job must end done
exactly once with a valid SVG, or failed with a clear message; none deleted, duplicated or stuck.

Real `facesvg serve` / `facesvg worker` processes on loopback, 6 s leases, bounded waits. Part of `make test`
(marked slow; see the report for its duration).
"""

from __future__ import annotations

import pytest

from web.faults import embedded_run, rq_run, second_serve_run

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("seed", [1, 2])
def test_kills_on_the_embedded_backend_lose_nothing(tmp_path, seed):
    out = embedded_run(tmp_path / "inst", seed, n=20, kills=2)
    assert out.jobs == 20 and sum(out.kills.values()) == 2
    assert (out.lost, out.duplicated, out.deleted, out.invalid) == (0, 0, 0, 0), out
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
    assert (out.done, out.failed, out.lost, out.duplicated, out.deleted, out.invalid) == (20, 0, 0, 0, 0, 0), out


@pytest.mark.parametrize("seed", [1])
def test_killed_rq_workers_lose_nothing(tmp_path, redis_url, seed):
    out = rq_run(tmp_path / "inst", redis_url, seed, n=20, kills=2)
    logs = f"{out}; the RQ workers' logs: {tmp_path}/rq-worker-*.log"
    assert out.jobs == 20 and sum(out.kills.values()) == 2
    assert (out.lost, out.duplicated, out.deleted, out.invalid) == (0, 0, 0, 0), logs
    assert out.done >= 18, logs
