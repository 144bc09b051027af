"""Uploads over the limit: the form says so before sending, the API answers 413 with a JSON message, and a client
that sends its whole body before reading (Python's urllib) gets that 413, not a reset connection."""

from __future__ import annotations

import io
import json
import urllib.error
import urllib.request

import pytest
from werkzeug.test import EnvironBuilder

from web.conftest import LiveServer, make_app
from webapp.limits import server_body_limit

KB = 1024
BOUNDARY = "facesvgtestboundary"


def multipart(size: int, name: str = "big.glb") -> bytes:
    """A multipart body whose 'file' part holds size bytes (a GLB header and zeros)."""
    head = (f"--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\n"
            "Content-Type: model/gltf-binary\r\n\r\n").encode()
    return head + b"glTF" + b"\0" * (size - 4) + f"\r\n--{BOUNDARY}--\r\n".encode()


def urllib_post(url: str, body: bytes) -> tuple[int, str, str]:
    """POST the whole body with urllib (which sends all of it before reading the answer): status, type, text."""
    request = urllib.request.Request(url + "/api/v1/jobs", data=body, method="POST",
                                     headers={"Content-Type": f"multipart/form-data; boundary={BOUNDARY}"})
    try:
        with urllib.request.urlopen(request, timeout=60) as r:
            return r.status, r.headers.get("Content-Type", ""), r.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers.get("Content-Type", ""), exc.read().decode()


def closed(app) -> None:
    app.extensions["facesvg_queue"].close()


@pytest.mark.parametrize("config, env, limit, text", [
    ({"MAX_CONTENT_LENGTH": 64 * KB}, {}, 64 * KB, "64 KB"),
    ({}, {"FACESVG_MAX_UPLOAD_MB": "3"}, 3 << 20, "3 MB"),
    ({}, {}, 100 << 20, "100 MB"),
])
def test_the_form_carries_the_servers_limit(tmp_path, monkeypatch, config, env, limit, text):
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    app = make_app(tmp_path, "embedded", **config)
    try:
        assert app.config["MAX_CONTENT_LENGTH"] == limit
        html = app.test_client().get("/").get_data(as_text=True)
        assert f'data-max-bytes="{limit}"' in html and f'data-max-text="{text}"' in html
        assert f"up to {text}" in html
        assert 'id="size-error"' in html
    finally:
        closed(app)


def test_the_413_names_the_limit_in_json_and_on_the_page(tmp_path):
    app = make_app(tmp_path, "embedded", MAX_CONTENT_LENGTH=64 * KB)
    try:
        c = app.test_client()
        r = c.post("/api/v1/jobs", data=multipart(100 * KB), content_type=f"multipart/form-data; boundary={BOUNDARY}")
        assert r.status_code == 413 and r.mimetype == "application/json"
        body = json.loads(r.get_data(as_text=True))
        assert body["status"] == 413 and "64 KB limit" in body["error"], body
        r = c.post("/jobs", data=multipart(100 * KB), content_type=f"multipart/form-data; boundary={BOUNDARY}")
        assert r.status_code == 413 and "64 KB limit" in r.get_data(as_text=True)
    finally:
        closed(app)


def test_openapi_documents_the_413_on_every_upload(tmp_path):
    app = make_app(tmp_path, "embedded")
    try:
        doc = app.test_client().get("/api/v1/openapi.json").get_json()
        uploads = [(path, method, op) for path, ops in doc["paths"].items() for method, op in ops.items()
                   if method != "parameters"
                   and "multipart/form-data" in (op.get("requestBody") or {}).get("content", {})]
        assert uploads, "no upload endpoint documented"
        for path, method, op in uploads:
            answer = op["responses"].get("413")
            assert answer, f"{method.upper()} {path} does not document its 413"
            assert answer["content"]["application/json"]["schema"] == {"$ref": "#/components/schemas/Error"}
            assert "FACESVG_MAX_UPLOAD_MB" in answer["description"]
    finally:
        closed(app)


def run_wsgi(app, body: bytes) -> tuple[str, io.BytesIO]:
    """Call the app as a WSGI server would; (status line, the input stream afterwards)."""
    stream = io.BytesIO(body)
    environ = EnvironBuilder(path="/api/v1/jobs", method="POST", input_stream=stream, content_length=len(body),
                             content_type=f"multipart/form-data; boundary={BOUNDARY}").get_environ()
    status = []
    b"".join(app(environ, lambda s, headers, exc_info=None: status.append(s)))
    return status[0], stream


def test_a_refused_body_is_read_to_its_end_within_the_drain_bound(tmp_path):
    app = make_app(tmp_path, "embedded", MAX_CONTENT_LENGTH=64 * KB, FACESVG_DRAIN_MB=1)
    try:
        bound = server_body_limit(app.config)
        assert bound == 64 * KB + (1 << 20) + (1 << 20)  # the limit, the form's slack, the drain
        within = multipart(bound - 4 * KB)
        status, stream = run_wsgi(app, within)
        assert status.startswith("413") and stream.tell() == len(within)  # all read: the client sees the answer
        beyond = multipart(bound + 64 * KB)
        status, stream = run_wsgi(app, beyond)
        assert status.startswith("413") and stream.tell() == 0  # refused from its declared length, left unread
    finally:
        closed(app)


def test_urllib_gets_the_413_from_the_development_server(tmp_path):
    server = LiveServer(make_app(tmp_path, "embedded", MAX_CONTENT_LENGTH=64 * KB))
    try:
        for size in (64 * KB + 200 * KB, 3 << 20):
            status, kind, text = urllib_post(server.url, multipart(size))
            assert status == 413 and kind.startswith("application/json"), (status, kind, text[:200])
            assert "64 KB limit" in json.loads(text)["error"]
    finally:
        server.close()


def test_urllib_gets_the_413_from_facesvg_serve(tmp_path):
    """waitress (`facesvg serve`) refuses a body past its own limit after the headers and closes the socket while
    the client still sends: the kernel resets the connection. Within the drain bound it reads the body, and the
    app's JSON 413 reaches the client."""
    from web.faults import Serve, oversized_post

    server = Serve(tmp_path / "inst", workers=1, env={"FACESVG_MAX_UPLOAD_MB": "1", "FACESVG_DRAIN_MB": "40"})
    server.wait_up()
    try:
        for size in ((1 << 20) + (512 * KB), 5 << 20, 30 << 20):  # slightly over; past limit + slack; far over
            status, kind, text = urllib_post(server.url, multipart(size))
            assert status == 413 and kind.startswith("application/json"), (size, status, kind, text[:200])
            assert "1 MB limit" in json.loads(text)["error"]
        answer, sent = oversized_post(server.port, 200 << 20)  # past the drain bound: refused from the headers
        assert answer.startswith(b"HTTP/1.1 413") and sent < 16 << 20, (answer[:60], sent)
    finally:
        server.stop()


@pytest.mark.browser
@pytest.mark.slow
def test_browser_the_form_names_the_file_over_the_limit(browser, tmp_path, artifacts):
    server = LiveServer(make_app(tmp_path, "embedded", MAX_CONTENT_LENGTH=64 * KB, WTF_CSRF_ENABLED=True))
    page = browser.new_page(viewport={"width": 1024, "height": 900})
    posts, inspected = [], []  # the form's submissions; what the page sent to /api/v1/inspect for suggestions

    def sent(request) -> None:
        if request.method == "POST":
            (inspected if request.url.endswith("/inspect") else posts).append(len(request.post_data_buffer or b""))
            if not request.url.endswith("/inspect"):
                posts[-1] = request.url

    page.on("request", sent)
    glb = "model/gltf-binary"
    try:
        page.goto(server.url + "/")
        assert not page.is_visible("#size-error")
        page.set_input_files("#file", {"name": "big.glb", "mimeType": glb, "buffer": b"glTF" + b"\0" * (100 * KB)})
        message = page.text_content("#size-error")
        assert page.is_visible("#size-error")
        assert "“big.glb” is 100 KB, over the 64 KB upload limit" in message, message
        page.screenshot(path=str(artifacts / "web_upload_too_large.png"))
        page.click("#convert")
        page.wait_for_timeout(500)
        assert posts == [] and page.url == server.url + "/"  # nothing was sent
        page.set_input_files("#file", {"name": "ok.glb", "mimeType": glb, "buffer": b"glTF" + b"\0" * (40 * KB)})
        assert not page.is_visible("#size-error")
        page.click("details.more summary")
        page.set_input_files("#file-cache", {"name": "take.pc2", "mimeType": "application/octet-stream",
                                             "buffer": b"\0" * (40 * KB)})
        assert "together, over the 64 KB upload limit" in page.text_content("#size-error")
        page.set_input_files("#file-cache", [])
        assert not page.is_visible("#size-error")
        # A file dropped on the drop zone is checked too.
        page.evaluate("""() => {
            const dt = new DataTransfer();
            dt.items.add(new File([new Uint8Array(90 * 1024)], 'dropped.glb', {type: 'model/gltf-binary'}));
            const drop = document.getElementById('drop');
            for (const type of ['dragenter', 'dragover', 'drop'])
              drop.dispatchEvent(new DragEvent(type, {dataTransfer: dt, bubbles: true, cancelable: true}));
        }""")
        assert page.text_content("#file-name") == "dropped.glb"
        assert "“dropped.glb” is 90 KB" in page.text_content("#size-error")
        page.click("#convert")
        page.wait_for_timeout(300)
        assert posts == []
        page.set_input_files("#file", {"name": "ok.glb", "mimeType": glb, "buffer": b"glTF" + b"\0" * (8 * KB)})
        page.click("#convert")  # within the limit: sent (the server then says what is wrong with the file)
        page.wait_for_load_state()
        assert posts and posts[0].endswith("/jobs")
        assert all(size <= 64 * KB for size in inspected), inspected  # a file over the limit is never sent
    finally:
        page.close()
        server.close()
