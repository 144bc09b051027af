"""The live page (/live): a puppet result driven by a `facesvg live` feed. The page's routes, links and feed checks
with the test client; then in headless Chromium the whole story: waiting for a bridge that is not up, connecting
by itself when it starts, Live Link Face packets sent over UDP arriving (state, packet counter, rate, bars, the
puppet's weights and pixels), a quiet feed, and the bridge stopping (the closed state and its reason)."""

from __future__ import annotations

import asyncio
import io
import re
import threading
import time
from html import unescape

import numpy as np
import pytest
from live.build import llf_curves, llf_packet, send
from PIL import Image
from puppet.faces import face_zip

from converter.formats.morphs import load_morph_face
from converter.live.packets import parse_livelink
from converter.live.ports import Ports
from converter.live.server import Bridge
from converter.options import ConversionOptions, Report
from converter.puppet import puppet_of
from converter.writers import puppet as puppet_writer
from web.conftest import LiveServer, free_port, make_app, workers_held
from webapp.jobstore import DONE, Job
from webapp.live import PORTS

PUPPET_ID, SVG_ID = "a" * 32, "b" * 32


@pytest.fixture(scope="module")
def puppet_html(tmp_path_factory) -> bytes:
    """A small generated face's puppet (jawOpen, mouthSmileLeft, eyeBlinkLeft, browInnerUp; two eyes)."""
    path = tmp_path_factory.mktemp("face") / "face.zip"
    path.write_bytes(face_zip())
    return puppet_writer.write(puppet_of(load_morph_face(path), ConversionOptions(size=256)), ConversionOptions(),
                               Report())


def plant(queue, job_id: str, to: str, name: str, main: tuple[str, bytes]) -> None:
    """A finished job of output kind `to` whose main file is main (stored name, bytes)."""
    now = time.time()
    result = {"report": {"counts": {}, "figures": {}, "sizes": {}, "warnings": []}, "frames": 1, "fps": 30.0,
              "duration": 0.033, "size": 256, "preview_frames": [], "still": None,
              "outputs": {to: len(main[1])}}
    queue.store.add(Job(id=job_id, state=DONE, stage="done", progress=1.0, filename=name, kind="zip",
                        options={"to": to, "size": 256}, files={"input": "input.zip"}, names={"input": name},
                        created=now - 5, started=now - 4, finished=now, result=result))
    (queue.storage.out(job_id) / main[0]).write_bytes(main[1])


@pytest.fixture
def app(tmp_path, puppet_html):
    application = make_app(tmp_path, "embedded")
    q = application.extensions["facesvg_queue"]
    plant(q, PUPPET_ID, "puppet", "smiley.zip", ("result.puppet.html", puppet_html))
    plant(q, SVG_ID, "svg", "flat.glb", ("result.svg", b'<svg xmlns="http://www.w3.org/2000/svg"/>'))
    yield application
    q.close()


def alert(page: str, element: str) -> str:
    found = re.search(rf'id="{element}">(.*?)</p>', page, re.DOTALL)
    return unescape(" ".join(found.group(1).split())) if found else ""


def test_the_page_is_linked_and_offers_the_users_puppets_with_the_bridge_command(app):
    c = app.test_client()
    home = c.get("/").get_data(as_text=True)
    assert re.search(r'<a href="/live" id="nav-live"', home)  # in the nav of every page
    r = c.get("/live")
    assert r.status_code == 200
    assert "connect-src 'self' ws: wss:" in r.headers["Content-Security-Policy"]  # the feed on its own port
    page = r.get_data(as_text=True)
    assert 'aria-current="page">Live</a>' in page
    # the user's puppet is offered and played (paused: the live feed drives it, not its embedded take); the SVG is not
    options = re.findall(r'<option value="([0-9a-f]{32})"', page)
    assert options == [PUPPET_ID]
    assert f'src="/api/v1/jobs/{PUPPET_ID}/result/puppet?paused=1"' in page
    assert f'data-feed="ws://127.0.0.1:{PORTS.ws}"' in page
    # the exact command and the ports each tracker sends to
    assert re.search(r'<code id="live-command">facesvg live --host 0.0.0.0</code>', page)
    for port in (PORTS.llf, PORTS.ifm, PORTS.vmc):
        assert f"<strong>{port}</strong>" in page
    # the puppet file is what the frame loads; it may open the WebSocket its user names, and load nothing else
    result = c.get(f"/api/v1/jobs/{PUPPET_ID}/result/puppet")
    assert result.data.startswith(b"<!")
    csp = result.headers["Content-Security-Policy"]
    assert "connect-src ws: wss:;" in csp and "default-src 'none'" in csp and "unsafe" not in csp
    # a puppet's result page links to the live page; another kind's does not
    assert f'href="/live?job={PUPPET_ID}"' in c.get(f"/jobs/{PUPPET_ID}").get_data(as_text=True)
    assert "/live?job=" not in c.get(f"/jobs/{SVG_ID}").get_data(as_text=True)


def test_another_port_is_in_the_command_and_the_feed(app):
    page = app.test_client().get("/live", query_string={"job": PUPPET_ID, "feed": "ws://127.0.0.1:9123"})
    text = page.get_data(as_text=True)
    assert page.status_code == 200 and 'data-feed="ws://127.0.0.1:9123"' in text
    assert '<code id="live-command">facesvg live --host 0.0.0.0 --ws-port 9123</code>' in text


@pytest.mark.parametrize("feed, words", [
    ("http://127.0.0.1:8765", "is a web page's address; a feed's starts with ws:// (here: ws://127.0.0.1:8765)"),
    ("ws://", "names no host"),
    ("ws://127.0.0.1:70000", "its port is not a number from 1 to 65535"),
    ("127.0.0.1:8765", "is not a WebSocket address"),
    ("ws://host name:8765", "has spaces in it"),
    ("ws://127.0.0.1:8765#x", "#fragment"),
    ("", "give the feed's WebSocket address"),
])
def test_a_bad_feed_address_says_why_and_is_not_connected_to(app, feed, words):
    r = app.test_client().get("/live", query_string={"feed": feed})
    page = r.get_data(as_text=True)
    assert r.status_code == 400
    assert words in alert(page, "feed-error")
    assert 'data-feed=""' in page and 'data-state="error"' in page  # the script connects to nothing
    assert "Traceback" not in page


def test_over_https_only_a_secure_feed_is_offered(app):
    c = app.test_client()
    r = c.get("/live", base_url="https://localhost", query_string={"feed": "ws://127.0.0.1:8765"})
    assert r.status_code == 400 and "only secure feeds (wss://)" in alert(r.get_data(as_text=True), "feed-error")
    assert c.get("/live", base_url="https://localhost", query_string={"feed": "wss://example.org/feed"}) \
        .status_code == 200


def test_a_missing_or_non_puppet_job_says_so(app):
    c = app.test_client()
    missing = c.get("/live", query_string={"job": "0" * 32})
    assert missing.status_code == 404 and "no such result" in alert(missing.get_data(as_text=True), "job-error")
    svg = c.get("/live", query_string={"job": SVG_ID})
    text = svg.get_data(as_text=True)
    assert svg.status_code == 400 and "not a puppet" in alert(text, "job-error")
    assert 'id="live-puppet"' not in text and 'id="live-no-puppet"' in text
    assert c.get("/live", query_string={"job": "../etc"}).status_code == 404


def test_the_sample_button_queues_the_samples_puppet_and_the_page_waits_for_it(app):
    q = app.extensions["facesvg_queue"]
    c = app.test_client()
    with workers_held(q):
        r = c.post("/live/sample", data={"feed": "ws://127.0.0.1:9000"})
        assert r.status_code == 303
        job_id = re.search(r"job=([0-9a-f]{32})", r.headers["Location"]).group(1)
        assert "feed=ws" in r.headers["Location"]
        job = q.get(job_id)
        assert job.options["to"] == "puppet" and job.filename == "face.glb" and job.state == "queued"
        page = c.get(r.headers["Location"]).get_data(as_text=True)
        assert 'id="building"' in page and 'http-equiv="refresh"' in page and 'id="live-puppet"' not in page
        q.delete(job_id)


def test_without_a_puppet_the_page_says_how_to_get_one(tmp_path):
    application = make_app(tmp_path, "embedded")
    try:
        page = application.test_client().get("/live").get_data(as_text=True)
        assert 'id="no-puppets"' in page and 'id="make-sample"' in page and 'id="live-no-puppet"' in page
    finally:
        application.extensions["facesvg_queue"].close()


class Feed:
    """`facesvg live`'s bridge (converter.live.server) in a thread of its own, its WebSocket on a given port."""

    def __init__(self, ws_port: int) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.bridge = Bridge("127.0.0.1", Ports(llf=0, ifm=0, vmc=0, ws=ws_port))
        asyncio.run_coroutine_threadsafe(self.bridge.start(), self.loop).result(10)
        self.llf = self.bridge.addresses["llf"][1]

    def close(self) -> None:
        """Close the sockets (players are sent a close frame) and stop the loop."""
        asyncio.run_coroutine_threadsafe(self.bridge.close(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


def state(page) -> str:
    return page.evaluate("() => document.getElementById('live').dataset.state")


def number(page, element: str) -> int:
    return int(page.inner_text(f"#{element}"))


def shot(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.locator("#live-puppet").screenshot())).convert("RGB"), np.int16)


@pytest.mark.browser
def test_a_live_stream_arrives_drives_the_puppet_and_closes(browser, app, artifacts):
    server = LiveServer(app)
    port = free_port()  # nothing listens here until the feed starts
    feed = None
    page = browser.new_page(viewport={"width": 1280, "height": 1000})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(f"{server.url}/live?feed=ws://127.0.0.1:{port}")
        # no bridge yet: the page says it is waiting, and how to start one
        page.wait_for_function("() => document.getElementById('live').dataset.state === 'waiting'", timeout=15000)
        assert f"nothing answers at ws://127.0.0.1:{port}" in page.inner_text("#live-status")
        assert page.inner_text("#live-command") == f"facesvg live --host 0.0.0.0 --ws-port {port}"
        page.wait_for_function("() => document.getElementById('live-puppet').contentDocument"
                               ".documentElement.dataset.puppet === 'ready'", timeout=60000)
        puppet = "document.getElementById('live-puppet').contentWindow.puppet"
        before = shot(page)
        assert page.evaluate(f"() => {puppet}.weights().jawOpen") == 0

        feed = Feed(port)  # the page tries again by itself and connects
        page.wait_for_function("() => ['open', 'quiet'].includes(document.getElementById('live').dataset.state)",
                               timeout=15000)
        counts, sent = [], []
        for k in range(60):  # 2 s of Live Link Face packets at 30 a second, over UDP to the bridge
            send(feed.llf, llf_packet(llf_curves(0.9, yaw=0.2), frame=k))
            sent.append(time.monotonic())
            time.sleep(1 / 30)
            if k in (20, 59):
                counts.append(number(page, "live-count"))
            if k == 45:  # the rate while packets flow, against what was sent in the second before (the page
                # counts the arrivals of the last second as of its last refresh, at most 0.25 s ago)
                rate, now = number(page, "live-rate"), time.monotonic()
                surely = sum(now - 1 <= t <= now - 0.25 for t in sent)  # in the page's window, whenever it looked
                recent = sum(now - 1.25 <= t for t in sent)  # all that can be
        assert state(page) == "live"
        page.wait_for_timeout(300)  # the counters are refreshed four times a second
        total = number(page, "live-count")
        assert 0 < counts[0] < counts[1] <= total <= 60, (counts, total)  # the counter rises with the packets
        assert surely // 2 <= rate <= recent, (rate, surely, recent)  # a rate (half: a loaded machine is late)
        assert "s ago" in page.inner_text("#live-age")
        # the strongest weights as bars: JawOpen 0.9 over every other weight's 0.1
        bars = page.eval_on_selector_all("#live-bars li", "els => els.map(e => [e.dataset.name, "
                                                          "e.querySelector('meter').value])")
        assert bars[0] == ["JawOpen", pytest.approx(0.9, abs=1e-6)] and len(bars) == 8
        assert all(v == pytest.approx(0.1, abs=1e-6) for _, v in bars[1:])
        yaw = np.degrees(parse_livelink(llf_packet(llf_curves(0.9, yaw=0.2))).head[0])  # the bridge's radians
        assert page.inner_text("#live-head") == f"{yaw:.1f}°, 0.0°, 0.0°"
        # the puppet follows: its weight, and its drawn pixels
        assert page.evaluate(f"() => {puppet}.weights().jawOpen") == pytest.approx(0.9, abs=1e-3)
        after = shot(page)
        changed = (np.abs(after - before).max(axis=2) > 40).mean()
        page.screenshot(path=str(artifacts / "web_live.png"), full_page=True)
        assert changed > 0.01, changed

        # the result page's own player takes the feed too (?live=, its Live field): its CSP lets it open a WebSocket
        direct = browser.new_page()
        try:
            direct.goto(f"{server.url}/api/v1/jobs/{PUPPET_ID}/result/puppet?live=ws://127.0.0.1:{port}")
            direct.wait_for_function("() => document.documentElement.dataset.puppet === 'ready'", timeout=60000)
            direct.wait_for_function("() => puppet.weights().jawOpen > 0.89", timeout=10000)  # the state at once
            send(feed.llf, llf_packet(llf_curves(0.3)))
            direct.wait_for_function("() => Math.abs(puppet.weights().jawOpen - 0.3) < 1e-3", timeout=10000)
        finally:
            direct.close()

        # the tracker stops sending: the page says for how long nothing came
        page.wait_for_function("() => document.getElementById('live').dataset.state === 'quiet'", timeout=10000)
        assert re.search(r"no packets for \d+ s", page.inner_text("#live-status"))

        feed.close()  # the bridge stops: closed, with the reason, and it stays so while retries find nothing
        feed = None
        page.wait_for_function("() => document.getElementById('live').dataset.state === 'closed'", timeout=10000)
        status = page.inner_text("#live-status")
        assert "Closed: the bridge stopped (going away), code 1001" in status, status
        assert page.text_content("#live-state") == "closed"
        page.wait_for_timeout(2500)  # one retry has failed by now
        assert state(page) == "closed"
        assert not errors, errors
    finally:
        page.close()
        if feed is not None:
            feed.close()
        server.server.shutdown()
        server.server.server_close()
