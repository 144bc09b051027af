"""Who may do what, limits before work, ownership of jobs, and the job page a user expects (issue 17)."""

from __future__ import annotations

import io
import re
import time
import uuid

import pytest

from converter.options import PRESETS
from web.conftest import SMALL, glb_bytes, make_app, wait_job, workers_held
from webapp.jobstore import DONE, QUEUED, RUNNING, Job


def post(client, headers=None, **fields):
    form = {**SMALL, "file": (io.BytesIO(glb_bytes()), "cube.glb"), **fields}
    return client.post("/api/v1/jobs", data=form, content_type="multipart/form-data", headers=headers or {})


@pytest.fixture
def embedded(tmp_path):
    app = make_app(tmp_path, "embedded")
    yield app
    app.extensions["facesvg_queue"].close()


def test_cross_site_posts_are_refused_and_same_site_ones_pass(embedded):
    c = embedded.test_client()
    n = len(embedded.extensions["facesvg_queue"].recent(100))
    for headers in ({"Origin": "http://evil.example"}, {"Origin": "null"},
                    {"Referer": "http://127.0.0.1:9999/attack.html"}):
        r = post(c, headers)
        assert r.status_code == 403, headers
        assert "another web site" in r.get_json()["error"]
    assert len(embedded.extensions["facesvg_queue"].recent(100)) == n  # nothing was queued
    assert post(c, {"Origin": "http://localhost"}).status_code == 202  # the test client's own origin
    assert post(c).status_code == 202  # a program (no Origin, no Referer)
    job = embedded.extensions["facesvg_queue"].recent(1)[0]
    assert c.delete(f"/api/v1/jobs/{job.id}", headers={"Origin": "http://evil.example"}).status_code == 403
    assert embedded.extensions["facesvg_queue"].get(job.id) is not None


def test_api_keys_are_required_and_scope_jobs(tmp_path):
    app = make_app(tmp_path, "embedded", FACESVG_API_KEYS="alpha-key, beta-key")
    try:
        c = app.test_client()
        assert post(c).status_code == 401
        assert c.get("/api/v1/jobs").status_code == 401
        assert post(c, {"Authorization": "Bearer wrong"}).status_code == 401
        assert c.get("/api/v1/health").status_code == 200  # liveness stays open
        a = post(c, {"Authorization": "Bearer alpha-key"}).get_json()["id"]
        b = post(c, {"X-API-Key": "beta-key"}).get_json()["id"]
        alpha, beta = {"Authorization": "Bearer alpha-key"}, {"X-API-Key": "beta-key"}
        assert [j["id"] for j in c.get("/api/v1/jobs", headers=alpha).get_json()["jobs"]] == [a]
        assert [j["id"] for j in c.get("/api/v1/jobs", headers=beta).get_json()["jobs"]] == [b]
        assert c.get(f"/api/v1/jobs/{b}", headers=alpha).status_code == 404
        assert c.delete(f"/api/v1/jobs/{b}", headers=alpha).status_code == 404
        assert app.extensions["facesvg_queue"].get(b) is not None  # alpha could not delete beta's job
        wait_job(_Keyed(c, beta), b)
        assert c.delete(f"/api/v1/jobs/{b}", headers=beta).status_code == 204
    finally:
        app.extensions["facesvg_queue"].close()


class _Keyed:
    """A test client that sends a header with every GET (for wait_job)."""

    def __init__(self, client, headers) -> None:
        self.client, self.headers = client, headers

    def get(self, url):
        return self.client.get(url, headers=self.headers)


def test_security_headers_on_every_response(embedded):
    c = embedded.test_client()
    for url in ("/", "/static/style.css", "/static/app.js", "/static/fap2d.html", "/no/such/page",
                "/api/v1/jobs", "/api/v1/jobs/" + "0" * 32, "/docs/api"):
        r = c.get(url)
        assert r.headers["X-Content-Type-Options"] == "nosniff", url
        assert r.headers["Referrer-Policy"] == "same-origin", url
        assert r.headers["X-Frame-Options"] == "SAMEORIGIN", url
        assert "frame-ancestors 'self'" in r.headers["Content-Security-Policy"], url
    page = c.get("/static/fap2d.html")
    csp = page.headers["Content-Security-Policy"]
    assert "connect-src 'self'" in csp and "'unsafe-inline'" not in csp
    # The page's own inline script is allowed by its hash, nothing else inline is.
    import base64
    import hashlib

    body = page.get_data(as_text=True)
    script = re.search(r"<script>(.*?)</script>", body, re.DOTALL).group(1)
    digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    assert f"'sha256-{digest}'" in csp
    assert "same-origin" in body or "origin === location.origin" in body
    cookie = c.get("/").headers.get("Set-Cookie", "")
    if cookie:  # the session cookie, when one is set
        assert "SameSite=Lax" in cookie and "HttpOnly" in cookie
    assert embedded.config["SESSION_COOKIE_SAMESITE"] == "Lax"


def test_rate_limit_and_queue_cap_answer_with_retry_after(tmp_path):
    app = make_app(tmp_path, "embedded", FACESVG_RATE_LIMIT=3, FACESVG_WORKERS=1)
    try:
        c = app.test_client()
        codes = [post(c).status_code for _ in range(5)]
        assert codes == [202, 202, 202, 429, 429]
        r = post(c)
        assert int(r.headers["Retry-After"]) >= 1 and "too many submissions" in r.get_json()["error"]
    finally:
        app.extensions["facesvg_queue"].close()
    app = make_app(tmp_path / "b", "embedded", FACESVG_QUEUE_CAP=2, FACESVG_RATE_LIMIT=0)
    q = app.extensions["facesvg_queue"]
    try:
        with workers_held(q):  # two jobs sit in the table, held running under a live lease no worker owns
            for i in range(2):
                q.store.add(Job(id=f"{i:032x}", created=time.time(), options={}, files={}))
                assert q.store.transition(f"{i:032x}", (QUEUED,), state=RUNNING, owner="held",
                                          lease=time.time() + 600)
        r = post(app.test_client())
        assert r.status_code == 503 and r.headers["Retry-After"] == "30"
        assert len(q.recent(10)) == 2  # nothing new was stored
    finally:
        q.close()


def test_bad_options_are_refused_at_submission(embedded):
    c = embedded.test_client()
    for fields, words in (({"frame": "9", "end": "3"}, "Still of frame"), ({"fps": "500"}, "fps"),
                          ({"start": "4", "end": "2"}, "End frame")):
        r = post(c, **fields)
        assert r.status_code == 400, fields
        error = r.get_json()["error"]
        assert words in error and "--" not in error, error
    assert embedded.extensions["facesvg_queue"].recent(10) == []


def test_html_form_keeps_the_options_after_an_error(embedded):
    c = embedded.test_client()
    r = c.post("/jobs", data={"size": "321", "start": "4", "end": "2", "file": (io.BytesIO(glb_bytes()), "c.glb")},
               content_type="multipart/form-data")
    html = r.get_data(as_text=True)
    assert r.status_code == 400 and "--end" not in html and "“End frame”" in html
    assert 'value="321"' in html  # the size typed is shown again


def test_try_again_refills_the_form_with_a_failed_jobs_options(embedded):
    q = embedded.extensions["facesvg_queue"]
    q.store.add(Job(id="a" * 32, state="failed", created=time.time(), message="the input is broken; see --fps.",
                    options={"size": 200, "max_triangles": 900, "shading": "gouraud"}))
    c = embedded.test_client()
    page = c.get("/jobs/" + "a" * 32).get_data(as_text=True)
    assert "--fps" not in page and "“Frames per second”" in page
    link = re.search(r'id="try-again" href="([^"]+)"', page).group(1)
    form = c.get(link.replace("&amp;", "&")).get_data(as_text=True)
    assert 'value="200"' in form and 'value="900"' in form and '"shading": "gouraud"' in form


def test_job_page_queue_position_eta_mobile_estimate_and_delete_confirmation(embedded):
    c = embedded.test_client()
    job = wait_job(c, post(c).get_json()["id"])
    assert job["state"] == "done" and job["eta_seconds"] is None and job["queue_position"] is None
    page = c.get(job["links"]["page"]).get_data(as_text=True)
    assert 'id="estimate-mobile"' in page and "Make a mobile version" in page
    assert 'id="delete-confirm"' in page and "Yes, delete it" in page
    form = c.get("/?preset=mobile&retry=" + job["id"]).get_data(as_text=True)
    mobile = PRESETS["mobile"].values
    assert f'value="{mobile["size"]}"' in form and f'value="{mobile["max_triangles"]}"' in form
    assert 'id="fig-playback"' in page  # the predicted playback class (converter.playcost)


def test_queue_position_and_eta_follow_the_queue_and_the_reported_progress(tmp_path):
    from types import SimpleNamespace

    from webapp.eta import standing
    from webapp.jobstore import SQLiteStore

    store = SQLiteStore(tmp_path / "t.sqlite3")
    now = time.time()
    store.add(Job(id="0" * 32, state=DONE, created=now - 100, started=now - 100, finished=now - 90))  # took 10 s
    store.add(Job(id="1" * 32, state=RUNNING, created=now - 5, started=now - 4, progress=0.5))  # 4 s more
    for i in range(2, 5):
        store.add(Job(id=str(i) * 32, state=QUEUED, created=now + i))
    queue = SimpleNamespace(store=store, recent=store.recent, workers=1)
    running = standing(queue, store.get("1" * 32))
    assert running["queue_position"] is None and running["eta_seconds"] == pytest.approx(4, abs=0.5)
    got = [standing(queue, store.get(str(i) * 32)) for i in range(2, 5)]
    assert [g["queue_position"] for g in got] == [1, 2, 3]
    # one worker: the first waits for the running job (about 4 s) then takes the typical 10 s; each next +10 s
    assert [g["eta_seconds"] for g in got] == pytest.approx([14, 24, 34], abs=0.6)
    queue.workers = 2  # a free worker: the first queued job starts at once
    assert standing(queue, store.get("2" * 32))["eta_seconds"] == pytest.approx(10, abs=0.1)
    store.close()


@pytest.mark.parametrize("backend", ["sqlite", "redis"])
def test_the_eta_counts_from_where_the_job_had_read_its_input(tmp_path, backend, request):
    # A job that spent 30 s loading (a face driven by a long capture), then did half of the rest in 10 s: 10 s
    # left, where extrapolating from its start says 40 s. A re-claimed job starts without an origin.
    from webapp.eta import remaining
    from webapp.jobstore import open_store
    from webapp.runner import ProgressRecorder

    url = request.getfixturevalue("redis_url") if backend == "redis" else f"sqlite:///{tmp_path / 't.sqlite3'}"
    store = open_store(url)
    job_id = uuid.uuid4().hex  # the session's Redis database is shared
    store.add(Job(id=job_id, created=time.time()))
    assert store.claim(job_id, "w", 60)
    clock = iter([1000.0, 1020.0, 1030.0, 1040.0])
    recorder = ProgressRecorder(store, job_id, interval=0, owner="w")
    real = time.time
    try:
        time.time = lambda: next(clock)
        recorder("load", 0.0)
        recorder("weights", 0.03)
        recorder("loaded", 0.0625)
        recorder("simplify", 0.53125)
    finally:
        time.time = real
    job = store.get(job_id)
    assert job.progress_origin == {"time": 1030.0, "progress": 0.0625}
    assert remaining(job, 20.0, now=1040.0) == pytest.approx(10.0, abs=0.01)  # progress is stored to 4 places
    job.progress_origin, job.started = {}, 1000.0
    assert remaining(job, 20.0, now=1040.0) == pytest.approx(35.3, abs=0.1)  # from the start, as before
    assert store.transition(job_id, (RUNNING,), state=QUEUED, owner="")
    assert store.claim(job_id, "w2", 60) and store.get(job_id).progress_origin == {}


def test_upload_form_has_the_mobile_preset_and_nav_links_the_api_page(embedded):
    c = embedded.test_client()
    html = c.get("/").get_data(as_text=True)
    mobile = PRESETS["mobile"].values
    assert 'id="preset-mobile"' in html and f'"max_triangles": {mobile["max_triangles"]}' in html
    assert f'"size": {mobile["size"]}' in html
    assert 'href="/docs/api"' in html
    docs = c.get("/docs/api").get_data(as_text=True)
    assert "<script" not in docs.split("</head>")[1].replace('<script type="application/json"', "")
    for op in ("createJob", "getJob", "deleteJob", "getResultKind"):
        assert f'id="{op}"' in docs
    assert "queue_position" in docs and "Retry-After" in docs


def test_a_lost_claim_discards_its_result_and_deletes_nothing(tmp_path):
    """A worker whose lease expired and whose job was re-queued can no longer record it, nor delete it."""
    from webapp.jobstore import SQLiteStore
    from webapp.lease import settle
    from webapp.runner import ProgressRecorder, _fail, execute
    from webapp.storage import Storage

    store, storage = SQLiteStore(tmp_path / "t.sqlite3"), Storage(tmp_path / "jobs")
    job_id = "b" * 32
    (storage.inputs(job_id) / "input.glb").write_bytes(glb_bytes())
    store.add(Job(id=job_id, created=time.time(), kind="glb", options={"size": 48, "occlusion": False},
                  files={"input": "input.glb"}))
    assert store.claim(job_id, "worker-a", 0.01)
    time.sleep(0.05)
    assert settle(store, storage, job_id, "worker-a", retries=1, why="test") == "requeued"
    assert _fail(store, storage, job_id, "worker-a", "late failure") == "lost"
    with pytest.raises(Exception) as exc:
        ProgressRecorder(store, job_id, interval=0, owner="worker-a")("convert", 0.5)
    assert type(exc.value).__name__ == "ClaimLost"
    assert store.get(job_id).state == QUEUED and (storage.job_dir(job_id) / "inputs").is_dir()
    assert store.claim(job_id, "worker-b", 60)
    assert execute(store, storage, job_id, "worker-a", 60, 2) == "lost"  # not a's job any more
    assert execute(store, storage, job_id, "worker-b", 60, 2) == DONE
    assert store.get(job_id).attempts == 2
    events = (storage.job_dir(job_id) / "events.log").read_text().split("\n")
    assert [e.split()[1:] for e in events if e] == [["discarded", "worker-a"], ["done", "worker-b"]]
    store.close()


def test_a_declared_300_mib_upload_is_refused_before_the_body_is_read(tmp_path):
    """`facesvg serve` (waitress) answers 413 right after the headers; the client sends almost nothing."""
    from web.faults import Serve, oversized_post

    server = Serve(tmp_path / "inst", workers=1).wait_up()
    try:
        answer, sent = oversized_post(server.port, 300 << 20)
        assert answer.startswith(b"HTTP/1.1 413"), answer[:80]
        assert sent < 8 << 20, sent  # refused early: at most a few socket buffers went out of 300 MiB
    finally:
        server.stop()


def test_a_chunked_upload_is_stopped_once_it_passes_the_limit(tmp_path):
    """No declared length: waitress counts the chunks as they arrive and answers 413 past the limit."""
    from web.faults import Serve, oversized_post

    server = Serve(tmp_path / "inst", workers=1, env={"FACESVG_MAX_UPLOAD_MB": "1"}).wait_up()
    try:
        answer, sent = oversized_post(server.port, 64 << 20, chunked=True)
        assert answer.startswith(b"HTTP/1.1 413"), answer[:80]
        limit = (1 << 20) + (1 << 20)  # the upload limit plus the room left for the form fields
        assert limit <= sent < limit + (8 << 20), sent  # stopped soon after the limit, far from the 64 MiB
    finally:
        server.stop()


def test_queue_cap_admissions_never_overshoot_under_a_concurrent_burst():
    import threading

    from webapp.limits import Admissions

    admissions, admitted, start = Admissions(), [], threading.Barrier(24)

    def submit():
        start.wait()
        if admissions.enter(active=3, cap=10):
            admitted.append(1)

    threads = [threading.Thread(target=submit) for _ in range(24)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(admitted) == 7  # 3 active + 7 in flight = the cap of 10, whatever the interleaving
    for _ in admitted:
        admissions.leave()
    assert admissions.enter(active=9, cap=10) and not admissions.enter(active=9, cap=10)
