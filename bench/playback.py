"""How an SVG plays in a real browser: Chromium's frame clock under CPU throttling (a phone stand-in).

One measurement opens the file as a document or inside an `<img>`, throttles the renderer's CPU through the
DevTools protocol, and reports frames per second by requestAnimationFrame, frames whose pixels changed (a
screencast: inside `<img>` the host page's rAF overstates playback), main-thread milliseconds per frame
(Performance.getMetrics TaskDuration), the time to the first frame, and the renderer's resident memory.
"""

from __future__ import annotations

import functools
import hashlib
import http.server
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import NamedTuple

from marionette_driver.errors import ScriptTimeoutException as MarionetteScriptTimeout
from marionette_driver.errors import TimeoutException as MarionetteTimeout
from playwright.sync_api import Browser
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from selenium.common.exceptions import TimeoutException as WebDriverTimeout

from tests.conftest import chromium_path, launched_chromium
from tests.engines import PAGE, Firefox, Session, WebKit, firefox_path, launched_firefox, launched_webkit, webkit_paths

THROTTLES = (1, 4, 6)  # CDP CPU throttling rates: a desktop, a mid-range phone, a low-end phone


# WebKitGTK 2.50 rasterises with Skia on OpenGL; on a machine without a GPU that is Mesa's llvmpipe, which made the
# default SVG several times slower than Skia on the CPU (an iPhone's WebKit draws on real hardware). This variable
# has it rasterise on the CPU, as headless Chromium does here.
WEBKIT_CPU_RASTER = {"WEBKIT_SKIA_ENABLE_CPU_RENDERING": "1"}
WEBKIT_CPU = "WebKitGTK (CPU raster)"


def installed_engines(unit: str = "column", cpu_raster: bool = False
                      ) -> tuple[list[tuple[str, Callable[[], AbstractContextManager[Session]]]], list[str]]:
    """Firefox ESR and WebKitGTK (and with cpu_raster WebKitGTK rasterising on the CPU, WEBKIT_CPU), each (name, a
    launcher of its tests/engines.py session) where installed, and a note for each one missing (its table loses
    that unit: "column", "rows", ...)."""
    engines, notes = [], []
    if firefox_path():
        engines.append(("Firefox ESR", lambda: launched_firefox(firefox_path())))
    else:
        notes.append(f"Firefox ESR is not installed: no Firefox {unit}.")
    if webkit_paths():
        engines.append(("WebKitGTK", lambda: launched_webkit(*webkit_paths())))
        if cpu_raster:
            engines.append((WEBKIT_CPU, lambda: launched_webkit(*webkit_paths(), env=WEBKIT_CPU_RASTER)))
    else:
        notes.append(f"WebKitGTK's WebKitWebDriver, MiniBrowser or Xvfb is missing: no WebKit {unit}.")
    return engines, notes


class Playback(NamedTuple):
    """What one file did in one mode at one throttling rate."""

    fps_raf: float  # requestAnimationFrame callbacks per second
    fps_changed: float  # screencast frames whose pixels changed, per second
    main_ms: float  # main-thread task milliseconds per rAF frame
    script_ms: float  # of which JavaScript, milliseconds per rAF frame
    first_frame_ms: float  # navigation start to the first animation frame after load
    renderer_mb: float  # resident memory of the renderer processes after the run
    state: object = None  # what the `state` expression of measure() gave at the end of the run


@contextmanager
def serve(folder: Path) -> Iterator[str]:
    """A loopback HTTP server for one folder, for the length of the block; yields its base URL."""
    handler = functools.partial(_QuietHandler, directory=str(folder))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args) -> None:
        pass


@contextmanager
def chromium() -> Iterator[Browser]:
    """Debian's Chromium, headless, driven by Playwright."""
    exe = chromium_path()
    if not exe:
        raise RuntimeError("Chromium is not installed (apt-get install chromium)")
    with launched_chromium(exe) as browser:
        yield browser


_START_RAF = """() => { window.__fsv = {n: 0, t0: null, t1: null, run: true};
  const c = window.__fsv;
  function tick(t) { if (c.t0 === null) c.t0 = t; else { c.n++; c.t1 = t; } if (c.run) requestAnimationFrame(tick); }
  requestAnimationFrame(tick); }"""
_STOP_RAF = """() => { const c = window.__fsv; c.run = false; return {n: c.n, dt: (c.t1 ?? c.t0 ?? 0) - (c.t0 ?? 0)}; }"""

_FIRST_FRAME = """() => new Promise((done) => requestAnimationFrame(() => done(performance.now())))"""


def host_page(svg_name: str, size: int) -> str:
    """An HTML page that shows the SVG as an image, the way a site embeds it."""
    return (f"<!doctype html><html><body style='margin:0'><img src='{svg_name}' width='{size}' height='{size}'>"
            "</body></html>")


def measure(browser: Browser, url: str, size: int, throttle: float, seconds: float,
            load_seconds: float = 300.0, state: str | None = None, warm: float = 0.0) -> Playback | None:
    """Play the page at url for `seconds` under `throttle`x CPU slowdown and measure it; None when it shows no
    frame within load_seconds. state: a JavaScript function evaluated in the page after the run (Playback.state);
    warm: seconds of play after the first frame before counting starts."""
    context = browser.new_context(viewport={"width": size, "height": size})
    page = context.new_page()
    cdp = context.new_cdp_session(page)
    try:
        cdp.send("Performance.enable")
        cdp.send("Emulation.setCPUThrottlingRate", {"rate": throttle})
        try:
            page.goto(url, wait_until="load", timeout=load_seconds * 1000)
            page.set_default_timeout(load_seconds * 1000)
            first = float(page.evaluate(_FIRST_FRAME))
            if warm > 0:
                page.wait_for_timeout(warm * 1000)
        except PlaywrightTimeout:
            return None
        changed = [0, ""]  # frames whose image differs from the previous one, last digest
        pending: list[int] = []  # screencast frames to acknowledge (never from inside the event handler)

        def on_frame(event: dict) -> None:
            digest = hashlib.sha1(event["data"].encode()).hexdigest()
            changed[0] += digest != changed[1]
            changed[1] = digest
            pending.append(event["sessionId"])

        cdp.on("Page.screencastFrame", on_frame)
        before = _task_seconds(cdp)
        script_before = _task_seconds(cdp, "ScriptDuration")
        cdp.send("Page.startScreencast", {"format": "jpeg", "quality": 40, "everyNthFrame": 1})
        page.evaluate(_START_RAF)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            page.wait_for_timeout(10)
            while pending:
                cdp.send("Page.screencastFrameAck", {"sessionId": pending.pop()})
        raf = page.evaluate(_STOP_RAF)
        cdp.send("Page.stopScreencast")
        after = _task_seconds(cdp)
        script_after = _task_seconds(cdp, "ScriptDuration")
        dt = max(raf["dt"], 1.0) / 1000.0
        n = max(int(raf["n"]), 1)
        return Playback(
            fps_raf=raf["n"] / dt,
            fps_changed=max(changed[0] - 1, 0) / dt,
            main_ms=1000.0 * (after - before) / n,
            script_ms=1000.0 * (script_after - script_before) / n,
            first_frame_ms=first,
            renderer_mb=renderer_rss_mb(browser),
            state=page.evaluate(state) if state else None,
        )
    finally:
        context.close()


# WebDriver / Marionette (the callback is the last argument): rAF callbacks over `secs` after `warm` seconds.
_SESSION_FPS = """const [warm, secs, done] = arguments;
setTimeout(() => {
  let n = 0, t0 = null, t1 = null;
  const tick = (t) => {
    if (t0 === null) t0 = t; else { n++; t1 = t; }
    if (t1 !== null && t1 - t0 >= secs * 1000) done({n, dt: t1 - t0}); else requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}, warm * 1000);"""


def session_fps(session: Session, url: str, warm: float, seconds: float) -> float:
    """requestAnimationFrame callbacks a second over `seconds` after `warm` seconds of play of the document at url
    (an SVG or a page), in a tests/engines.py session (Firefox ESR, WebKitGTK)."""
    session.navigate(url)
    got = session.run_async(_SESSION_FPS, float(warm), float(seconds))
    return float(got["n"]) / (max(float(got["dt"]), 1.0) / 1000.0)


ENGINE_WARM_S, ENGINE_PLAY_S = 1.0, 5.0  # issue 49: rAF counted over 5 s after 1 s of play
_ENGINE_TIMEOUTS = (MarionetteTimeout, MarionetteScriptTimeout, WebDriverTimeout, TimeoutError)


def svg_engine_fps(session: Session, document: bytes, mode: str = "document", warm: float = ENGINE_WARM_S,
                   seconds: float = ENGINE_PLAY_S, limit: float = 120.0) -> float | None:
    """rAF fps of an SVG (mode "document": the file itself; "inline": in an HTML page) or an HTML page (mode
    "page") in a tests/engines.py session; None when loading or playing takes over `limit` seconds (the page may
    then still be busy: close the session)."""
    suffix = {"document": ".svg", "inline": ".html", "page": ".html"}[mode]
    if mode == "inline":
        document = (PAGE % document.decode("utf-8")).encode("utf-8")
    _session_timeouts(session, limit)
    with tempfile.TemporaryDirectory(prefix="facesvg-fps-") as tmp:
        path = Path(tmp) / f"played{suffix}"
        path.write_bytes(document)
        try:
            return session_fps(session, path.as_uri(), warm, seconds)
        except _ENGINE_TIMEOUTS:
            return None


def _session_timeouts(session: Session, seconds: float) -> None:
    """The session's page-load and script timeouts (each protocol sets them its own way)."""
    if isinstance(session, Firefox):
        session.client.timeout.page_load = seconds
        session.client.timeout.script = seconds
    elif isinstance(session, WebKit):
        session.driver.set_page_load_timeout(seconds)
        session.driver.set_script_timeout(seconds)


def _task_seconds(cdp, metric: str = "TaskDuration") -> float:
    metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
    return float(metrics.get(metric, 0.0))


def renderer_rss_mb(browser: Browser) -> float:
    """Resident memory of the browser's renderer processes (MiB), read from /proc by their pids."""
    session = browser.new_browser_cdp_session()
    try:
        info = session.send("SystemInfo.getProcessInfo")["processInfo"]
    finally:
        session.detach()
    total = 0
    for proc in info:
        if proc.get("type") != "renderer":
            continue
        try:
            for line in Path(f"/proc/{proc['id']}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except OSError:
            continue
    return total / 1024.0
