"""The embedded backend survives a restart: the job table persists; interrupted jobs are re-queued or failed."""

from __future__ import annotations

import io
import time

import pytest

from web.conftest import SMALL, glb_bytes, make_app, wait_job
from webapp.jobstore import RUNNING, Job


def _stored_job(queue, job_id: str, state: str, attempts: int) -> None:
    """A job record as a dying server would have left it, with its input on disk."""
    (queue.storage.inputs(job_id) / "input.glb").write_bytes(glb_bytes())
    queue.store.add(Job(id=job_id, created=time.time(), filename="cube.glb", kind="glb",
                        options={"size": 64, "occlusion": False}, files={"input": "input.glb"}))
    if state == RUNNING:
        assert queue.store.transition(job_id, ("queued",), state=RUNNING, attempts=attempts, progress=0.4)


@pytest.mark.slow
def test_restart_keeps_jobs_and_recovers_interrupted_ones(tmp_path):
    first = make_app(tmp_path, "embedded", FACESVG_EXECUTOR="process", FACESVG_WORKERS=1)
    c = first.test_client()
    r = c.post("/api/v1/jobs", data={"file": (io.BytesIO(glb_bytes()), "cube.glb"), **SMALL},
               content_type="multipart/form-data")
    done = wait_job(c, r.get_json()["id"])
    assert done["state"] == "done"
    first.extensions["facesvg_queue"].close()  # the server stops ...
    # ... and, as if it had died mid-way, leaves jobs behind in every unfinished state.
    from webapp.jobs import EmbeddedQueue
    from webapp.storage import Storage

    raw = EmbeddedQueue.__new__(EmbeddedQueue)  # table access only, no pool
    from webapp.jobstore import SQLiteStore

    raw.store = SQLiteStore(tmp_path / "instance" / "jobs.sqlite3")
    raw.storage = Storage(tmp_path / "instance" / "jobs")
    _stored_job(raw, "1" * 32, RUNNING, attempts=1)  # interrupted once: re-queued
    _stored_job(raw, "2" * 32, RUNNING, attempts=2)  # interrupted twice: failed
    _stored_job(raw, "3" * 32, "queued", attempts=0)  # never started: run after the restart
    raw.store.close()

    second = make_app(tmp_path, "embedded", FACESVG_EXECUTOR="process", FACESVG_WORKERS=1)
    try:
        q = second.extensions["facesvg_queue"]
        assert q.recovered == {"requeued": ["1" * 32], "failed": ["2" * 32]}
        c = second.test_client()
        again = c.get(f"/api/v1/jobs/{done['id']}").get_json()
        assert again["state"] == "done" and again["result"] == done["result"]
        assert c.get(f"/api/v1/jobs/{done['id']}/result").data.startswith(b"<")
        failed = c.get("/api/v1/jobs/" + "2" * 32).get_json()
        assert failed["state"] == "failed" and "server stopped" in failed["error"]
        for job_id in ("1" * 32, "3" * 32):
            assert wait_job(c, job_id)["state"] == "done"
        assert q.store.get("1" * 32).attempts == 2
        assert len(c.get("/api/v1/jobs").get_json()["jobs"]) == 4  # none lost
    finally:
        second.extensions["facesvg_queue"].close()


@pytest.mark.slow
def test_server_stopped_mid_job_requeues_it_on_start(tmp_path):
    """A real `facesvg serve` stopped (SIGTERM) while converting: after a restart the job completes."""
    import os
    import subprocess
    import sys

    import requests

    from conftest import ROOT
    from web.conftest import free_port

    def serve(port: int) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-m", "converter.cli", "serve", "--port", str(port), "--workers", "1",
                                 "--instance", str(tmp_path / "inst")], cwd=ROOT,
                                env=dict(os.environ, PYOPENGL_PLATFORM="egl"),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(200):
            try:
                requests.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=1)
                return proc
            except requests.ConnectionError:
                time.sleep(0.1)
        raise AssertionError("server did not start")

    port = free_port()
    proc = serve(port)
    url = f"http://127.0.0.1:{port}/api/v1/jobs"
    job_id = requests.post(url, data={"size": "384", "occlusion": "1"},
                           files={"file": ("cube.glb", glb_bytes(n_keys=60))}, timeout=30).json()["id"]
    end = time.monotonic() + 60
    while requests.get(f"{url}/{job_id}", timeout=10).json()["state"] != "running" and time.monotonic() < end:
        time.sleep(0.02)
    proc.terminate()
    proc.wait(30)
    from webapp.jobstore import SQLiteStore

    store = SQLiteStore(tmp_path / "inst" / "jobs.sqlite3")
    assert store.get(job_id).state == "running"  # left behind by the stopped server
    store.close()
    port = free_port()
    proc = serve(port)
    try:
        url = f"http://127.0.0.1:{port}/api/v1/jobs"
        end = time.monotonic() + 120
        while (job := requests.get(f"{url}/{job_id}", timeout=10).json())["state"] not in ("done", "failed"):
            assert time.monotonic() < end
            time.sleep(0.1)
        assert job["state"] == "done" and job["result"]["frames"] > 0
    finally:
        proc.terminate()
        proc.wait(30)


def test_a_job_table_from_an_older_release_gains_the_new_columns(tmp_path):
    """A SQLite job table written before leases, clients and the ETA's origin existed opens, keeps its jobs, and
    they run with the new fields at their defaults."""
    import json
    import sqlite3

    from webapp.jobstore import QUEUED, SQLiteStore

    path = tmp_path / "jobs.sqlite3"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE jobs (id TEXT PRIMARY KEY, state TEXT, stage TEXT, progress REAL, message TEXT, "
               "filename TEXT, kind TEXT, options TEXT, files TEXT, created REAL, started REAL, finished REAL, "
               "attempts INTEGER, result TEXT)")
    db.execute("INSERT INTO jobs VALUES (?, ?, 'queued', 0, '', 'a.glb', 'glb', ?, ?, ?, NULL, NULL, 0, '{}')",
               ("f" * 32, QUEUED, json.dumps({"size": 48}), json.dumps({"input": "input.glb"}), time.time()))
    db.commit()
    db.close()
    store = SQLiteStore(path)
    job = store.get("f" * 32)
    assert (job.state, job.options, job.owner, job.lease, job.client, job.progress_origin) == \
        (QUEUED, {"size": 48}, "", 0.0, "", {})
    assert store.claim_next("w", 60) == "f" * 32
    assert store.transition("f" * 32, (RUNNING,), holder="w", progress_origin={"time": 5.0, "progress": 0.05})
    assert store.get("f" * 32).progress_origin == {"time": 5.0, "progress": 0.05}
    store.close()
