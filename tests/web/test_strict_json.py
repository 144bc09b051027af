"""Strict JSON everywhere in the web app: a NaN or infinity in a stored report never reaches a client, and one
broken job record never breaks the job list or another job's page."""

from __future__ import annotations

import io
import json
import math
import re
import time

import pytest
from flask import jsonify, render_template_string

from web.conftest import SMALL, LiveServer, glb_bytes, make_app, wait_job
from webapp import runner
from webapp.jobstore import DONE, RUNNING, Job

NAN_ID, BROKEN_ID, ODD_ID, GOOD_ID = "a" * 32, "b" * 32, "c" * 32, "d" * 32
SVG = b'<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><rect width="64" height="32"/></svg>'


def strict(text: str):
    """json.loads that refuses NaN, Infinity and -Infinity, as browsers and strict clients do."""
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


def report(figure: float) -> dict:
    """A report as the converter writes it, with one figure that could not be measured."""
    return {"counts": {"triangles": 12, "triangles_kept": 12, "frames": 4},
            "figures": {"budget_deviation_mean_px": figure, "max_deviation_px": 0.25, "worst_px": math.inf},
            "sizes": {}, "warnings": []}


def nan_result() -> dict:
    return {"report": report(math.nan), "frames": 4, "fps": math.nan, "duration": math.inf, "size": 64,
            "preview_frames": [], "still": None, "outputs": {"svg": len(SVG), "report": 10},
            "media_type": "image/svg+xml"}


def plant_raw(queue, job_id: str, column: str, text: str) -> None:
    """Write a column of a stored record as given, the way the store wrote JSON columns before (json.dumps, which
    writes a bare NaN), or as a broken disk or an old version may have left it."""
    store = queue.store
    if hasattr(store, "redis"):
        store.redis.hset(store._key(job_id), column, text)
    else:
        store._conn().execute(f"UPDATE jobs SET {column} = ? WHERE id = ?", (text, job_id))


def plant_done(queue, job_id: str, result: dict, filename: str = "avatar.glb") -> None:
    """A finished job whose stored result and report file hold what result holds (NaN included)."""
    now = time.time()
    queue.store.add(Job(id=job_id, state=DONE, stage="done", progress=1.0, filename=filename, kind="glb",
                        options={"to": "svg", "shading": "flat", "size": 64}, created=now - 5, started=now - 4,
                        finished=now))
    plant_raw(queue, job_id, "result", json.dumps(result))  # json.dumps: a bare NaN, as before
    out = queue.storage.out(job_id)
    (out / "result.svg").write_bytes(SVG)
    (out / "report.json").write_text(json.dumps(result["report"], indent=1))


def no_nan(text: str) -> bool:
    return not re.search(r"\b(nan|inf|infinity)\b", text, re.IGNORECASE)


def test_a_nan_report_is_served_as_strict_json_everywhere(app, client):
    q = app.extensions["facesvg_queue"]
    plant_done(q, NAN_ID, nan_result())
    job = strict(client.get(f"/api/v1/jobs/{NAN_ID}").get_data(as_text=True))
    assert job["state"] == "done"
    figures = job["result"]["report"]["figures"]
    assert figures["budget_deviation_mean_px"] is None and figures["worst_px"] is None
    assert figures["max_deviation_px"] == 0.25  # finite figures are untouched
    assert job["result"]["fps"] is None and job["result"]["duration"] is None
    listed = strict(client.get("/api/v1/jobs").get_data(as_text=True))["jobs"]
    assert [j["id"] for j in listed] == [NAN_ID]
    served = client.get(f"/api/v1/jobs/{NAN_ID}/result/report")
    assert served.status_code == 200
    assert strict(served.get_data(as_text=True))["figures"]["budget_deviation_mean_px"] is None
    page = client.get(f"/jobs/{NAN_ID}").get_data(as_text=True)
    assert 'id="player"' in page and no_nan(page), re.findall(r".{40}\bnan\b.{20}", page, re.I)
    figures_html = page.split('id="fidelity"')[1].split("</dl>")[0]
    assert re.search(r"Mean shape change from the triangle budget</dt><dd[^>]*>—</dd>", figures_html)
    assert re.search(r"Largest drawing error, measured</dt><dd[^>]*>0.25 px</dd>", figures_html)
    assert no_nan(client.get("/jobs").get_data(as_text=True)) and no_nan(client.get("/").get_data(as_text=True))


def test_the_store_writes_no_nan_and_reads_old_nan_as_null(app):
    q = app.extensions["facesvg_queue"]
    q.store.add(Job(id=GOOD_ID, state=DONE, created=time.time(), result=nan_result(), progress=math.nan))
    store = q.store
    if hasattr(store, "redis"):
        raw = store.redis.hget(store._key(GOOD_ID), "result").decode()
    else:
        raw = store._conn().execute("SELECT result FROM jobs WHERE id = ?", (GOOD_ID,)).fetchone()[0]
    assert strict(raw)["report"]["figures"]["budget_deviation_mean_px"] is None  # stored as null
    assert q.get(GOOD_ID).progress == 0.0
    plant_raw(q, GOOD_ID, "result", '{"fps": NaN, "duration": Infinity, "x": [-Infinity, 1e999, 2.5]}')
    assert q.get(GOOD_ID).result == {"fps": None, "duration": None, "x": [None, None, 2.5]}


def test_the_json_provider_never_writes_nan(app):
    assert app.json.dumps({"a": math.nan, "b": [math.inf, 1.5], "c": {"d": -math.inf}}) == \
        '{"a": null, "b": [null, 1.5], "c": {"d": null}}'
    with app.test_request_context():
        assert strict(jsonify(x=math.nan).get_data(as_text=True)) == {"x": None}
        assert render_template_string("{{ v|tojson }}", v={"x": math.nan}) == '{"x": null}'


def test_a_broken_job_never_breaks_the_list_or_another_page(app, client):
    q = app.extensions["facesvg_queue"]
    plant_done(q, NAN_ID, nan_result())
    plant_done(q, BROKEN_ID, nan_result(), filename="broken.glb")
    plant_raw(q, BROKEN_ID, "result", '{"report": {"figures": {')  # cut off mid-write
    plant_done(q, ODD_ID, nan_result(), filename="odd.glb")  # parses, but is no result the pages can show
    plant_raw(q, ODD_ID, "result", json.dumps({"preview_frames": "abc", "frames": "x", "outputs": [1]}))
    plant_done(q, GOOD_ID, {**nan_result(), "fps": 10.0, "duration": 0.4}, filename="good.glb")
    plant_raw(q, GOOD_ID, "options", json.dumps({"to": "svg", "size": 64, "shading": "flat"}))
    r = client.get("/api/v1/jobs")
    assert r.status_code == 200
    jobs = {j["id"]: j for j in strict(r.get_data(as_text=True))["jobs"]}
    assert set(jobs) == {NAN_ID, BROKEN_ID, ODD_ID, GOOD_ID}
    assert jobs[GOOD_ID]["state"] == "done" and jobs[GOOD_ID]["result"]["fps"] == 10.0
    assert jobs[NAN_ID]["state"] == "done"
    for bad in (BROKEN_ID, ODD_ID):
        assert jobs[bad]["state"] == "failed" and "damaged" in jobs[bad]["error"], jobs[bad]
        one = strict(client.get(f"/api/v1/jobs/{bad}").get_data(as_text=True))
        assert one["state"] == "failed" and "delete the job" in one["error"]
        page = client.get(f"/jobs/{bad}")
        assert page.status_code == 200 and "damaged" in page.get_data(as_text=True)
    listing = client.get("/jobs")
    assert listing.status_code == 200
    html = listing.get_data(as_text=True)
    assert all(name in html for name in ("good.glb", "broken.glb", "odd.glb", "avatar.glb"))
    good = client.get(f"/jobs/{GOOD_ID}").get_data(as_text=True)
    assert 'id="player"' in good and "10 fps" in good
    assert client.delete(f"/api/v1/jobs/{BROKEN_ID}").status_code == 204  # a broken job can be removed
    assert BROKEN_ID not in {j["id"] for j in strict(client.get("/api/v1/jobs").get_data(as_text=True))["jobs"]}


def test_a_garbled_record_and_report_file(app, client):
    q = app.extensions["facesvg_queue"]
    plant_done(q, NAN_ID, nan_result())
    plant_done(q, GOOD_ID, nan_result())
    plant_raw(q, NAN_ID, "state", '"exploded"' if hasattr(q.store, "redis") else "exploded")
    plant_raw(q, NAN_ID, "progress", '"abc"' if hasattr(q.store, "redis") else "abc")
    (q.storage.out(GOOD_ID) / "report.json").write_text('{"figures": {"x": 1')
    jobs = {j["id"]: j for j in strict(client.get("/api/v1/jobs").get_data(as_text=True))["jobs"]}
    assert jobs[NAN_ID]["state"] == "failed" and "state" in jobs[NAN_ID]["error"]
    assert jobs[GOOD_ID]["state"] == "done"
    r = client.get(f"/api/v1/jobs/{GOOD_ID}/result/report")
    assert r.status_code == 500 and "damaged" in strict(r.get_data(as_text=True))["error"]


def test_sqlite_text_that_is_not_utf8_breaks_only_its_own_job(tmp_path):
    app = make_app(tmp_path, "embedded")
    try:
        q, c = app.extensions["facesvg_queue"], app.test_client()
        plant_done(q, GOOD_ID, nan_result(), filename="good.glb")
        plant_done(q, BROKEN_ID, nan_result())
        q.store._conn().execute("UPDATE jobs SET filename = CAST(X'FFFE41' AS TEXT), options = "
                                "CAST(X'7BFF' AS TEXT) WHERE id = ?", (BROKEN_ID,))
        jobs = {j["id"]: j for j in strict(c.get("/api/v1/jobs").get_data(as_text=True))["jobs"]}
        assert jobs[GOOD_ID]["state"] == "done" and jobs[BROKEN_ID]["state"] == "failed"
        assert c.get("/jobs").status_code == 200 and c.get("/").status_code == 200
    finally:
        app.extensions["facesvg_queue"].close()


def test_the_runner_stores_a_report_without_nan(tmp_path, monkeypatch):
    """A figure the verifier could not measure (NaN) is null in the stored report, the record and the API."""
    monkeypatch.setattr(runner, "fidelity", lambda svg, anim: {"max_deviation_px": math.nan, "spread": math.inf,
                                                                "tolerance_px": 0.5})
    app = make_app(tmp_path, "embedded")  # thread workers: the patched verifier runs
    try:
        q, client = app.extensions["facesvg_queue"], app.test_client()
        r = client.post("/api/v1/jobs", data={**SMALL, "file": (io.BytesIO(glb_bytes()), "cube.glb")},
                        content_type="multipart/form-data")
        job_id = r.get_json()["id"]
        assert wait_job(client, job_id)["state"] == "done"
        text = client.get(f"/api/v1/jobs/{job_id}").get_data(as_text=True)
        figures = strict(text)["result"]["report"]["figures"]
        assert figures["max_deviation_px"] is None and figures["spread"] is None and figures["tolerance_px"] == 0.5
        stored = strict((q.storage.result_path(job_id, "report")).read_text())
        assert stored["figures"]["max_deviation_px"] is None
        raw = q.store._conn().execute("SELECT result FROM jobs WHERE id = ?", (job_id,)).fetchone()[0]
        assert strict(raw)["report"]["figures"]["spread"] is None
    finally:
        app.extensions["facesvg_queue"].close()


@pytest.fixture
def live(tmp_path):
    s = LiveServer(make_app(tmp_path, "embedded"))
    yield s
    s.close()


def running_job(queue, job_id: str) -> None:
    """A job some (other) worker holds, with a lease far from running out: it stays running until we say."""
    now = time.time()
    queue.store.add(Job(id=job_id, state=RUNNING, stage="prerender", progress=0.91, filename="avatar.glb",
                        kind="glb", options={"to": "svg", "shading": "flat", "size": 64}, created=now - 5,
                        started=now - 4, owner="elsewhere", lease=now + 3600))


@pytest.mark.browser
@pytest.mark.slow
def test_browser_poll_shows_an_error_after_garbage_answers(browser, live):
    q = live.app.extensions["facesvg_queue"]
    running_job(q, NAN_ID)
    page = browser.new_page()
    hits = []

    def garbage(route):
        hits.append(route.request.url)
        route.fulfill(status=200, content_type="application/json", body='{"state": NaN, <html>')

    try:
        page.route(f"**/api/v1/jobs/{NAN_ID}", garbage)
        page.goto(f"{live.url}/jobs/{NAN_ID}")
        assert page.text_content("#job-state") == "running"
        page.wait_for_selector("#poll-error", state="visible", timeout=30_000)
        assert page.text_content("#job-state") == "unknown"
        assert "lost touch" in page.text_content("#poll-error")
        seen = len(hits)
        assert seen == 5, hits
        page.wait_for_timeout(1500)
        assert len(hits) == seen  # it stopped asking
    finally:
        page.close()


@pytest.mark.browser
@pytest.mark.slow
def test_browser_a_job_that_finishes_with_nan_shows_its_finished_state(browser, live, artifacts):
    q = live.app.extensions["facesvg_queue"]
    running_job(q, NAN_ID)
    page = browser.new_page()
    try:
        page.goto(f"{live.url}/jobs/{NAN_ID}")
        assert page.text_content("#job-state") == "running"
        out = q.storage.out(NAN_ID)
        (out / "result.svg").write_bytes(SVG)
        (out / "report.json").write_text(json.dumps(report(math.nan)))
        assert q.store.transition(NAN_ID, (RUNNING,), state=DONE, stage="done", progress=1.0, finished=time.time(),
                                  owner="", lease=0.0)
        plant_raw(q, NAN_ID, "result", json.dumps(nan_result()))  # as the old runner stored it: a bare NaN
        page.wait_for_selector("#player", timeout=30_000)  # the poll read the answer and reloaded
        assert page.text_content("#job-state") == "done"
        text = page.inner_text("body")
        assert no_nan(text), text
        figures = page.inner_html("#fidelity")
        assert re.search(r"Mean shape change from the triangle budget</dt><dd[^>]*>—</dd>", figures)
        page.screenshot(path=str(artifacts / "web_nan_job.png"), full_page=True)
    finally:
        page.close()
