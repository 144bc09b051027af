"""Twenty uploads at once through a real HTTP server: all complete, none lost, each result intact."""

from __future__ import annotations

import threading
import time

import pytest
import requests
from lxml import etree

from web.conftest import SMALL, LiveServer, glb_bytes, make_app


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["embedded", "rq"])
def test_twenty_concurrent_uploads_all_complete(request, tmp_path, backend):
    url = None
    if backend == "rq":
        url = request.getfixturevalue("redis_url")
        request.getfixturevalue("rq_worker")
    server = LiveServer(make_app(tmp_path, backend, url, FACESVG_EXECUTOR="process", FACESVG_WORKERS=2))
    try:
        n = 20
        barrier = threading.Barrier(n)
        ids: list[str | None] = [None] * n
        errors: list[str] = []

        def upload(i: int) -> None:
            barrier.wait()
            try:
                r = requests.post(f"{server.url}/api/v1/jobs", data={**SMALL, "yaw": str(i)},
                                  files={"file": (f"cube{i}.glb", glb_bytes())}, timeout=60)
                r.raise_for_status()
                ids[i] = r.json()["id"]
            except Exception as exc:  # collected and asserted below
                errors.append(repr(exc))

        threads = [threading.Thread(target=upload, args=(i,)) for i in range(n)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not errors and len(set(ids)) == n
        end = time.monotonic() + 240
        states = {}
        while time.monotonic() < end:
            states = {i: requests.get(f"{server.url}/api/v1/jobs/{i}", timeout=10).json()["state"] for i in ids}
            if all(s in ("done", "failed") for s in states.values()):
                break
            time.sleep(0.5)
        failed = [requests.get(f"{server.url}/api/v1/jobs/{i}", timeout=10).json()["error"]
                  for i, s in states.items() if s != "done"]
        assert set(states.values()) == {"done"}, failed[:3]
        listed = requests.get(f"{server.url}/api/v1/jobs?limit=100", timeout=10).json()["jobs"]
        assert {j["id"] for j in listed} == set(ids)
        yaws = set()
        for i, job_id in enumerate(ids):
            job = requests.get(f"{server.url}/api/v1/jobs/{job_id}", timeout=10).json()
            assert job["filename"] == f"cube{i}.glb"
            yaws.add(job["options"]["yaw"])
            svg = requests.get(f"{server.url}/api/v1/jobs/{job_id}/result", timeout=10).content
            assert etree.fromstring(svg).tag.endswith("svg")
        assert yaws == {float(i) for i in range(n)}  # each job kept its own options
    finally:
        server.close()
