"""REST API and HTML routes through the Flask test client, on both backends (embedded and RQ)."""

from __future__ import annotations

import io
import json
import re
import stat
import time
import zipfile

import pytest
from lxml import etree

from web.conftest import SMALL, glb_bytes, make_app, wait_job, workers_held
from webapp.jobstore import RUNNING, Job


def post(client, data: bytes | None = b"", name: str = "cube.glb", url: str = "/api/v1/jobs", **fields):
    form = {**SMALL, **fields}
    if data is not None:
        form["file"] = (io.BytesIO(data), name)
    return client.post(url, data=form, content_type="multipart/form-data")


def converted(client, **fields) -> dict:
    r = post(client, glb_bytes(), yaw="30", pitch="20", **fields)
    assert r.status_code == 202, r.get_json()
    assert r.headers["Location"].endswith(r.get_json()["id"])
    return wait_job(client, r.get_json()["id"])


def test_submit_poll_and_fetch_every_result(client):
    job = converted(client)
    assert job["state"] == "done" and job["percent"] == 100 and job["error"] is None
    res = job["result"]
    assert res["frames"] == res["report"]["counts"]["frames"] >= 4 and res["fps"] > 0
    assert res["report"]["counts"]["triangles"] == 12
    figures = res["report"]["figures"]  # measured by the verifier against the exact projection
    assert figures["within_tolerance"] is True and 0 <= figures["max_deviation_px"] <= figures["tolerance_px"]
    svg = client.get(job["links"]["result"])
    assert svg.status_code == 200 and svg.mimetype == "image/svg+xml"
    root = etree.fromstring(svg.data)
    assert root.tag == "{http://www.w3.org/2000/svg}svg" and root.findall(".//{*}animate")
    assert "default-src 'none'" in svg.headers["Content-Security-Policy"]
    assert set(job["links"]["results"]) == {"svg", "svgz", "report"}
    svgz = client.get(job["links"]["results"]["svgz"])
    import gzip

    assert gzip.decompress(svgz.data) == svg.data and "attachment" in svgz.headers["Content-Disposition"]
    report = client.get(job["links"]["results"]["report"]).get_json()
    assert report["counts"] == res["report"]["counts"]
    dl = client.get(job["links"]["results"]["svg"] + "?download=1")
    assert 'attachment; filename=cube.svg' in dl.headers["Content-Disposition"]
    assert len(res["preview_frames"]) == 4  # FACESVG_PREVIEW_FRAMES in the test config
    assert res["preview_frames"][0] == 0 and res["preview_frames"][-1] == res["frames"] - 1
    pngs = [client.get(job["links"]["previews"][str(k)]).data for k in res["preview_frames"]]
    assert all(p[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert pngs[0] != pngs[-1]  # the morph animates: first and last prerender differ
    assert client.get(f"/api/v1/jobs/{job['id']}/preview/99").status_code == 404
    listed = client.get("/api/v1/jobs").get_json()["jobs"]
    assert [j["id"] for j in listed] == [job["id"]]


def test_still_frame_job_shows_that_frame(client):
    job = converted(client, frame="2")
    assert job["state"] == "done", job["error"]
    assert job["result"]["still"] == 2 and job["result"]["preview_frames"] == [2]
    html = client.get(job["links"]["page"]).get_data(as_text=True)
    assert "SVG still of frame 2" in html and 'id="play"' not in html and "/preview/2" in html


def test_job_pages(client):
    job = converted(client)
    page = client.get(job["links"]["page"])
    assert page.status_code == 200
    html = page.get_data(as_text=True)
    assert 'id="svg-view"' in html and 'id="prerender"' in html and 'id="frame-slider"' in html
    assert "SVGZ" in html and 'id="fig-triangles"' in html
    assert "X-Frame-Options" in page.headers and "Content-Security-Policy" in page.headers
    assert client.get("/").status_code == 200
    jobs = client.get("/jobs").get_data(as_text=True)
    assert job["links"]["page"] in jobs
    r = client.post(f"/jobs/{job['id']}/delete")
    assert r.status_code == 303
    assert client.get(job["links"]["page"]).status_code == 404
    assert client.post(f"/jobs/{job['id']}/delete").status_code == 404
    assert client.post("/jobs/not-an-id/delete").status_code == 404


def test_html_submit_redirects_and_shows_progress(app, client):
    r = client.post("/jobs", data={"file": (io.BytesIO(glb_bytes()), "cube.glb"), **SMALL},
                    content_type="multipart/form-data")
    assert r.status_code == 303
    job_id = r.headers["Location"].rsplit("/", 1)[-1]
    html = client.get(f"/jobs/{job_id}").get_data(as_text=True)
    assert 'data-status-url="/api/v1/jobs/' in html or 'id="player"' in html
    assert wait_job(client, job_id)["state"] == "done"
    bad = client.post("/jobs", data={"size": "64"}, content_type="multipart/form-data")
    assert bad.status_code == 400 and "choose an animation file" in bad.get_data(as_text=True)


def test_user_text_is_escaped(client):
    job = converted(client, **{})
    evil = "<img src=x onerror=alert(1)>.glb"
    r = post(client, glb_bytes(), name=evil)
    job_id = r.get_json()["id"]
    wait_job(client, job_id)
    for url in (f"/jobs/{job_id}", "/jobs", "/"):
        html = client.get(url).get_data(as_text=True)
        assert "<img src=x" not in html and "&lt;img src=x onerror=alert(1)&gt;.glb" in html
    svg = client.get(f"/api/v1/jobs/{job_id}/result").data
    assert b"<script" not in svg
    assert job["state"] == "done"


def test_failing_conversion_marks_job_failed_and_server_keeps_serving(client):
    broken = json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": []}]}).encode()
    r = post(client, broken, name="empty.gltf")
    assert r.status_code == 202
    job = wait_job(client, r.get_json()["id"])
    assert job["state"] == "failed" and job["error"] and "\n" not in job["error"]
    assert client.get(f"/api/v1/jobs/{job['id']}/result").status_code == 409
    page = client.get(f"/jobs/{job['id']}").get_data(as_text=True)
    assert 'id="job-error"' in page
    assert converted(client)["state"] == "done"  # the next job still runs


@pytest.mark.parametrize("fields, data, message", [
    ({}, None, "choose an animation file"),
    ({"size": "huge"}, b"x", "size must be"),
    ({"size": "4"}, b"x", "size must be between"),
    ({"shading": "phong"}, b"x", "unknown shading"),
    ({"colour": "red"}, b"x", "unknown field"),
    ({}, b"not an animation at all\x00\x01", "not a glTF"),
    ({}, b"", "choose an animation file"),
    ({"to": "fap2d"}, b"x", "FAP stream and an FDP"),
    ({}, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "point cache"),
    ({}, json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": "../../etc/passwd", "byteLength": 4}]}).encode(),
     "external files"),
])
def test_bad_submissions_are_refused_with_a_clear_message(app, client, fields, data, message):
    r = post(client, data, name="in.bin", **fields)
    assert r.status_code == 400
    assert message in r.get_json()["error"]
    assert app.extensions["facesvg_queue"].storage.job_ids() == []  # nothing half-stored
    assert client.get("/api/v1/jobs").get_json()["jobs"] == []


def _zip(entries: list[tuple[str, bytes]], symlink: str | None = None) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in entries:
            zf.writestr(name, data)
        if symlink:
            info = zipfile.ZipInfo(symlink)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zf.writestr(info, "/etc/passwd")
    return buf.getvalue()


@pytest.mark.parametrize("archive, message", [
    (_zip([("../evil.obj", b"v 0 0 0\n")]), "unsafe path"),
    (_zip([("/abs/frame1.obj", b"v 0 0 0\n")]), "unsafe path"),
    (_zip([("frame1.obj", b"v 0 0 0\n")], symlink="frame2.obj"), "symbolic link"),
    (_zip([("frame1.obj", b"\0" * (8 << 20))]), "zip bomb"),
    (b"PK\x03\x04garbage", "damaged"),
])
def test_unsafe_zips_are_refused_before_the_job_runs(app, client, archive, message):
    r = post(client, archive, name="frames.zip")
    assert r.status_code == 400 and message in r.get_json()["error"]
    assert app.extensions["facesvg_queue"].storage.job_ids() == []


def test_zip_expanding_beyond_the_limit_is_refused(tmp_path):
    app = make_app(tmp_path, "embedded", FACESVG_MAX_UNZIPPED_MB=1)
    try:
        data = _zip([(f"f{i}.obj", bytes(range(256)) * 2048) for i in range(3)])
        r = post(app.test_client(), data, name="big.zip")
        assert r.status_code == 400 and "expands to" in r.get_json()["error"]
    finally:
        app.extensions["facesvg_queue"].close()


def test_upload_too_large_gives_413_json_and_friendly_page(tmp_path):
    app = make_app(tmp_path, "embedded", MAX_CONTENT_LENGTH=2048)
    try:
        c = app.test_client()
        r = post(c, b"glTF" + b"\0" * 5000)
        assert r.status_code == 413 and "limit" in r.get_json()["error"]
        r = c.post("/jobs", data={"file": (io.BytesIO(b"\0" * 5000), "big.glb")}, content_type="multipart/form-data")
        assert r.status_code == 413
        html = r.get_data(as_text=True)
        assert "File too large" in html and "<html" in html
    finally:
        app.extensions["facesvg_queue"].close()


def test_unknown_and_unfinished_jobs(app, client):
    assert client.get("/api/v1/jobs/" + "0" * 32).status_code == 404
    assert client.get("/api/v1/jobs/../../etc").status_code == 404
    assert client.get("/api/v1/jobs/nothex").get_json()["status"] == 404
    assert client.delete("/api/v1/jobs/" + "0" * 32).status_code == 404
    assert client.get("/jobs/" + "0" * 32).status_code == 404
    assert "<html" in client.get("/jobs/" + "0" * 32).get_data(as_text=True)
    assert client.get("/api/v1/jobs?limit=x").status_code == 400
    q = app.extensions["facesvg_queue"]
    with workers_held(q):
        q.store.add(Job(id="a" * 32, created=time.time()))  # a queued record no worker was told about
        assert client.get("/api/v1/jobs/" + "a" * 32).get_json()["state"] == "queued"
        assert client.get("/api/v1/jobs/" + "a" * 32 + "/result").status_code == 409
        assert client.get("/api/v1/jobs/" + "a" * 32 + "/result/svg").status_code == 409
        assert client.get("/api/v1/jobs/" + "a" * 32 + "/result/exe").status_code == 404
        assert client.get("/api/v1/jobs/" + "a" * 32 + "/preview/0").status_code == 409
        page = client.get("/jobs/" + "a" * 32).get_data(as_text=True)
        assert 'id="progress"' in page


def test_delete_semantics(app, client):
    q = app.extensions["facesvg_queue"]
    with workers_held(q):  # the queued and the running record must stay as planted
        # queued -> cancelled and removed
        q.store.add(Job(id="b" * 32, created=time.time()))
        q.storage.inputs("b" * 32)
        assert client.delete("/api/v1/jobs/" + "b" * 32).status_code == 204
        assert client.get("/api/v1/jobs/" + "b" * 32).status_code == 404
        assert "b" * 32 not in q.storage.job_ids()
        # running -> 202 cancelling; the worker's next progress step stops it and removes the job
        q.store.add(Job(id="c" * 32, created=time.time()))
        assert q.store.claim("c" * 32)
        r = client.delete("/api/v1/jobs/" + "c" * 32)
        assert r.status_code == 202 and r.get_json()["state"] == "cancelling"
        from webapp.runner import JobCancelled, ProgressRecorder

        with pytest.raises(JobCancelled):
            ProgressRecorder(q.store, "c" * 32)("extract", 0.5)
    # finished -> 204 and the files are gone
    job = converted(client)
    assert client.delete(f"/api/v1/jobs/{job['id']}").status_code == 204
    assert client.get(f"/api/v1/jobs/{job['id']}").status_code == 404
    assert job["id"] not in q.storage.job_ids()


def test_cancel_a_running_job_end_to_end(app, client):
    """A real job cancelled while running: it disappears and its folder is removed."""
    q = app.extensions["facesvg_queue"]
    r = post(client, glb_bytes(n_keys=40), size="256", occlusion="1", yaw="30")
    job_id = r.get_json()["id"]
    end = time.monotonic() + 60
    while q.store.get(job_id).state != RUNNING and time.monotonic() < end:
        time.sleep(0.01)
    outcome = client.delete(f"/api/v1/jobs/{job_id}").status_code
    assert outcome in (202, 204)  # 204 only if it had already finished
    end = time.monotonic() + 60
    while client.get(f"/api/v1/jobs/{job_id}").status_code != 404 and time.monotonic() < end:
        time.sleep(0.05)
    assert client.get(f"/api/v1/jobs/{job_id}").status_code == 404
    time.sleep(0.3)
    assert job_id not in q.storage.job_ids()


def test_retention_cleanup_removes_old_jobs(app, client):
    job = converted(client)
    q = app.extensions["facesvg_queue"]
    assert q.cleanup(3600) == []  # young jobs stay
    orphan = q.storage.inputs("d" * 32)
    assert orphan.exists()
    import os

    os.utime(q.storage.job_dir("d" * 32), (0, 0))
    app.config["FACESVG_RETENTION_HOURS"] = 0
    removed = app.extensions["facesvg_cleanup"].maybe_run(force=True)
    assert set(removed) == {job["id"], "d" * 32}
    assert client.get(f"/api/v1/jobs/{job['id']}").status_code == 404
    assert q.storage.job_ids() == []


def test_bundled_sample_one_click(tmp_path, tiny_glb):
    app = make_app(tmp_path, "embedded", FACESVG_SAMPLE=str(tiny_glb))
    try:
        c = app.test_client()
        r = c.post("/jobs", data={"sample": "1", **SMALL}, content_type="multipart/form-data")
        assert r.status_code == 303
        assert wait_job(c, r.headers["Location"].rsplit("/", 1)[-1])["state"] == "done"
        app.config["FACESVG_SAMPLE"] = str(tmp_path / "missing.glb")
        r = post(c, None, sample="1")
        assert r.status_code == 400 and "bundled sample is missing" in r.get_json()["error"]
    finally:
        app.extensions["facesvg_queue"].close()


def test_csrf_protects_html_forms(tmp_path):
    app = make_app(tmp_path, "embedded", WTF_CSRF_ENABLED=True)
    try:
        c = app.test_client()
        r = c.post("/jobs", data={"file": (io.BytesIO(glb_bytes()), "cube.glb"), **SMALL},
                   content_type="multipart/form-data")
        assert r.status_code == 400 and "security token" in r.get_data(as_text=True)
        assert c.get("/api/v1/jobs").get_json()["jobs"] == []
        token = re.search(r'name="csrf_token" value="([^"]+)"', c.get("/").get_data(as_text=True)).group(1)
        r = c.post("/jobs", data={"csrf_token": token, "file": (io.BytesIO(glb_bytes()), "cube.glb"), **SMALL},
                   content_type="multipart/form-data")
        assert r.status_code == 303
        # the JSON API takes no session cookie and needs no token
        assert post(c, glb_bytes()).status_code == 202
    finally:
        app.extensions["facesvg_queue"].close()


def test_health_and_openapi(app, client):
    assert client.get("/api/v1/health").get_json() == {"status": "ok", "backend": app.extensions["facesvg_queue"].name}
    doc = client.get("/api/v1/openapi.json").get_json()
    assert doc["openapi"].startswith("3.")


def test_openapi_documents_exactly_the_routes(app):
    doc = app.test_client().get("/api/v1/openapi.json").get_json()
    documented = {(path, m.upper()) for path, ops in doc["paths"].items() for m in ops if m != "parameters"}
    routed = set()
    for rule in app.url_map.iter_rules():
        if not rule.rule.startswith("/api/v1/"):
            continue
        path = re.sub(r"<(?:[a-z]+:)?([a-z_]+)>", r"{\1}", rule.rule[len("/api/v1"):])
        for m in rule.methods - {"HEAD", "OPTIONS"}:
            routed.add((path, m))
    assert documented == routed
    for path, ops in doc["paths"].items():  # every path parameter is declared
        declared = {p["name"] for p in ops.get("parameters", [])}
        assert set(re.findall(r"{([a-z_]+)}", path)) == declared
