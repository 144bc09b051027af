"""Web UI fixtures: a tiny animated glTF, apps on the embedded or RQ backend, a real redis-server, a live server."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import SAMPLE, cube_animation

SMALL = {"size": "64", "occlusion": "0"}  # keeps conversions in tests fast


def glb_bytes(n_keys: int = 4, fps: float = 10.0) -> bytes:
    """A cube whose top face rises over n_keys frames, written by the product's own glTF writer."""
    from converter.animation import FaceAnimation
    from converter.export.glb import write_glb

    cube = cube_animation(1)
    pos = cube.frames[0]
    delta = np.zeros_like(pos)
    delta[pos[:, 1] > 0, 1] = 0.8
    frames = pos[None] + np.linspace(0, 1, n_keys, dtype=np.float32)[:, None, None] * delta[None]
    return write_glb(FaceAnimation(frames, cube.faces, cube.part_ids, cube.parts, fps, "cube"))


@pytest.fixture(scope="session")
def tiny_glb(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("inputs") / "cube.glb"
    path.write_bytes(glb_bytes())
    return path


@pytest.fixture(scope="session")
def sample_file(tiny_glb) -> Path:
    """The bundled sample if present, else the tiny cube (so the UI tests run before the sample lands)."""
    return SAMPLE if SAMPLE.is_file() else tiny_glb


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def redis_url(tmp_path_factory):
    """A real redis-server on a free loopback port (skipped without it locally; a failure under CI)."""
    exe = shutil.which("redis-server")
    if not exe:
        if os.environ.get("CI"):
            pytest.fail("redis-server is not installed but CI is set: .ci/run must install it")
        pytest.skip("redis-server not installed (apt-get install redis-server)")
    port = free_port()
    folder = tmp_path_factory.mktemp("redis")
    proc = subprocess.Popen([exe, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no",
                             "--dir", str(folder)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    import redis

    client = redis.Redis(port=port)
    for _ in range(100):
        try:
            client.ping()
            break
        except redis.ConnectionError:
            time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("redis-server did not start")
    yield f"redis://127.0.0.1:{port}/0"
    proc.terminate()
    proc.wait(10)


@pytest.fixture(scope="session")
def rq_worker(redis_url):
    """One RQ worker process (`facesvg worker`) working the queue for the whole session."""
    import sys

    env = dict(os.environ, PYOPENGL_PLATFORM="egl")
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-m", "converter.cli", "worker", "--queue", redis_url], cwd=root,
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    yield proc
    proc.terminate()
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        proc.kill()


def make_app(tmp_path: Path, backend: str, redis_url: str | None = None, **config):
    """An app with its own instance folder on the named backend ('embedded' or 'rq')."""
    from webapp import create_app

    base = {"INSTANCE_PATH": str(tmp_path / "instance"), "TESTING": True, "WTF_CSRF_ENABLED": False,
            "FACESVG_EXECUTOR": "thread", "FACESVG_WORKERS": 2, "FACESVG_PREVIEW_FRAMES": 4}
    if backend == "rq":
        import redis

        redis.Redis.from_url(redis_url).flushdb()
        base["FACESVG_QUEUE"] = redis_url
    base.update(config)
    return create_app(base)


@pytest.fixture(params=["embedded", "rq"])
def app(request, tmp_path):
    """The app on each backend (same tests for both)."""
    url = None
    if request.param == "rq":
        url = request.getfixturevalue("redis_url")
        request.getfixturevalue("rq_worker")
    application = make_app(tmp_path, request.param, url)
    yield application
    application.extensions["facesvg_queue"].close()


@pytest.fixture
def client(app):
    return app.test_client()


@contextlib.contextmanager
def workers_held(queue):
    """Embedded backend: no worker claims while inside (records added as queued stay queued); then new workers.

    The embedded workers claim any queued row of the table within a poll, so a test that plants a queued
    record and expects it to stay queued races them without this. RQ workers take only what is enqueued.
    """
    from webapp.workers import WorkerPool

    pool = getattr(queue, "pool", None)
    if pool is None:
        yield
        return
    pool.close(wait=True)
    try:
        yield
    finally:
        queue.pool = WorkerPool(queue.store, queue.storage, queue.workers, queue.kind, queue.lease_seconds,
                                queue.retries, queue.preview_frames)


def wait_job(client, job_id: str, timeout: float = 120.0) -> dict:
    """Poll the API until the job leaves queued/running; returns its JSON."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        data = client.get(f"/api/v1/jobs/{job_id}").get_json()
        if data["state"] in ("done", "failed", "cancelled"):
            return data
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} did not finish in {timeout} s: {data}")


class LiveServer:
    """A threaded WSGI server for an app in a background thread on 127.0.0.1 and a free port."""

    def __init__(self, app) -> None:
        from werkzeug.serving import make_server

        self.app = app
        self.server = make_server("127.0.0.1", free_port(), app, threaded=True)
        self.url = f"http://127.0.0.1:{self.server.server_port}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()  # stops serve_forever cleanly before the socket closes
        self.server.server_close()
        self.thread.join(timeout=10)
        self.app.extensions["facesvg_queue"].close()
