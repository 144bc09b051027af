"""Other output kinds and the command line: the fap2d package through the API, `facesvg serve/worker`."""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
import time
import urllib.parse
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SAMPLE, SMALL_DATA
from web.conftest import wait_job

FAP = SMALL_DATA / "mpeg4" / "xface" / "joy.fap"
FDP = ROOT / "samples" / "face.fdp.json"


@pytest.mark.slow
@pytest.mark.parametrize("app", ["embedded"], indirect=True)
def test_fap2d_package_job_embeds_the_player(client):
    if not (FAP.is_file() and FDP.is_file() and SAMPLE.is_file()):
        pytest.fail("the fap2d test needs samples/face.glb, samples/face.fdp.json and tests/data's Xface FAP files")
    r = client.post("/api/v1/jobs", data={
        "file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb"), "to": "fap2d", "size": "128", "end": "12",
        "fap": (io.BytesIO(FAP.read_bytes()), "joy.fap"), "fdp": (io.BytesIO(FDP.read_bytes()), "face.fdp.json"),
    }, content_type="multipart/form-data")
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    assert set(job["links"]["results"]) == {"fap2d", "report"}
    pkg = client.get(job["links"]["result"])
    assert pkg.mimetype == "application/zip" and "attachment" in pkg.headers["Content-Disposition"]
    names = zipfile.ZipFile(io.BytesIO(pkg.data)).namelist()
    assert "manifest.json" in names
    html = client.get(job["links"]["page"]).get_data(as_text=True)
    src = re.search(r'<iframe id="fap2d-view"[^>]* src="([^"]+)"', html).group(1).replace("&amp;", "&")
    url = urllib.parse.urlsplit(src)
    assert url.path == "/static/fap2d.html"
    assert urllib.parse.parse_qs(url.query)["src"] == [job["links"]["results"]["fap2d"]]
    assert client.get(job["links"]["previews"]["0"]).mimetype == "image/png"
    # the prerender follows the FAP stream (the 3D face it drives), frame for frame with the package
    assert job["result"]["frames"] == job["result"]["report"]["counts"]["frames"] > 12


@pytest.mark.slow
def test_cli_registers_serve_and_worker():
    from converter.cli import build_parser

    args = build_parser().parse_args(["serve", "--host", "0.0.0.0", "--port", "8123", "--workers", "3"])
    assert (args.host, args.port, args.workers) == ("0.0.0.0", 8123, 3)
    out = subprocess.run([sys.executable, "-m", "converter.cli", "worker", "--queue", "embedded"],
                         capture_output=True, text=True, cwd=Path(ROOT))
    assert out.returncode == 2 and "redis://" in out.stderr and "Traceback" not in out.stderr
    for bad in ("0", "ten", "1e9"):  # refused before it loads anything or connects
        out = subprocess.run([sys.executable, "-m", "converter.cli", "worker", "--queue", "redis://127.0.0.1:9/0"],
                             capture_output=True, text=True, cwd=Path(ROOT),
                             env={**os.environ, "FACESVG_RQ_MAINTENANCE_SECONDS": bad})
        assert out.returncode == 2 and "FACESVG_RQ_MAINTENANCE_SECONDS" in out.stderr, out.stderr
        assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr


def test_a_job_sets_its_3d_frames_aside_while_the_writer_runs(tmp_path, monkeypatch):
    """The runner keeps the prepared animation for the verifier and the prerender, but not in memory while the
    writer runs (its peak): the frames wait in an anonymous file, and what is verified and drawn is still them."""
    import weakref

    from converter.outputs import output_kind
    from web.conftest import glb_bytes
    from webapp import runner
    from webapp.jobstore import DONE, Job, SQLiteStore
    from webapp.storage import Storage

    refs, alive, verified = [], [], []
    real_convert, kind = runner.convert, output_kind("svg")
    real_write, real_verify = kind.shading_writers["flat"], runner.verify_animation

    def convert(*args, on_prepared, **kwargs):
        def seen(anim):
            refs.append((weakref.ref(anim.frames), anim.frames.copy()))
            on_prepared(anim)
        return real_convert(*args, on_prepared=seen, **kwargs)

    def write(*args, **kwargs):
        alive.extend(ref() is not None for ref, _ in refs)  # no gc.collect: freed by reference counting
        return real_write(*args, **kwargs)

    def verify(svg, anim):
        verified.append(np.array_equal(anim.frames, refs[0][1]))
        return real_verify(svg, anim)

    monkeypatch.setattr(runner, "convert", convert)
    monkeypatch.setattr(runner, "verify_animation", verify)
    monkeypatch.setitem(kind.shading_writers, "flat", write)
    store, storage = SQLiteStore(tmp_path / "t.sqlite3"), Storage(tmp_path / "jobs")
    job_id = "c" * 32
    (storage.inputs(job_id) / "input.glb").write_bytes(glb_bytes())
    store.add(Job(id=job_id, created=time.time(), kind="glb", options={"size": 48}, files={"input": "input.glb"}))
    assert store.claim(job_id, "w", 60)
    assert runner.execute(store, storage, job_id, "w", 60, 2) == DONE
    job = store.get(job_id)
    store.close()
    assert alive == [False] and verified == [True]
    assert job.result["report"]["figures"]["within_tolerance"] and job.result["preview_frames"]
    assert sorted(p.name for p in storage.job_dir(job_id).iterdir()) == ["events.log", "inputs", "out"]


@pytest.mark.slow
@pytest.mark.parametrize("app", ["embedded"], indirect=True)
def test_puppet_job_with_a_take_is_served_with_its_own_player(client):
    take = SMALL_DATA / "captures" / "livelinkface_myslate3_cut.csv"
    r = client.post("/api/v1/jobs", data={
        "file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb"), "to": "puppet", "size": "128",
        "weights": (io.BytesIO(take.read_bytes()), "MySlate_3.csv"),
    }, content_type="multipart/form-data")
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    html = client.get(job["links"]["result"])
    assert html.mimetype == "text/html" and b"window.puppet" in html.data
    page = client.get(job["links"]["page"]).get_data(as_text=True)
    assert 'data-viewer="frame"' in page and "MySlate_3.csv" in page


@pytest.mark.slow
@pytest.mark.parametrize("app", ["embedded"], indirect=True)
@pytest.mark.parametrize("to, media", [("lottie", "application/json"), ("dotlottie", "application/zip")])
def test_lottie_jobs_download_what_the_players_read(client, to, media):
    """A web job to Lottie or dotLottie finishes, is verified like an SVG, downloads as an attachment of its
    media type, and its page shows the result (a Lottie's own metadata names the frames it holds)."""
    r = client.post("/api/v1/jobs", data={"file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb"), "to": to,
                                          "size": "128", "end": "10"}, content_type="multipart/form-data")
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    got = client.get(job["links"]["result"])
    assert got.mimetype == media and "attachment" in got.headers["Content-Disposition"]
    data = got.data
    if to == "dotlottie":
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            assert "manifest.json" in z.namelist()
            data = z.read("animations/face.json")
    doc = json.loads(data)
    assert doc["op"] == job["result"]["report"]["counts"]["frames"] == 10 and doc["layers"]
    assert job["result"]["report"]["figures"]["max_deviation_px"] <= 0.25 + 1e-9
    page = client.get(job["links"]["page"])
    assert page.status_code == 200 and to in page.get_data(as_text=True)
