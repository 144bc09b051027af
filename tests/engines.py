"""Draw a page or an SVG paused at chosen times in Firefox ESR and WebKitGTK, as tests/svgrender.py does in Chromium.

Firefox is Debian's `firefox-esr`, headless, driven over Marionette (its built-in automation protocol, through
Mozilla's `marionette-driver` client: Debian packages no geckodriver). WebKit is Debian's WebKitGTK: its
`WebKitWebDriver` (package webkit2gtk-driver) starts the MiniBrowser it ships in automation mode, on an Xvfb
display of our own (WebKitGTK has no headless mode), driven by Selenium. One session serves many pages.

Neither engine screenshots with a transparent background, so an SVG is shot twice, over black and over white:
a pixel of colour c and coverage a shows a*c over black and a*c + (1 - a)*255 over white, which gives a and c
back exactly (up to 8-bit rounding) and so the RGBA that Chromium's `omit_background` screenshot gives.
"""

from __future__ import annotations

import contextlib
import glob
import io
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from converter.writers import svg_anim, svg_gouraud

# Every SVG output kind the engines are compared on: writer and options (besides the size). "merged" is
# --max-animations: paths of several triangles (subpaths), keyed together.
SVG_OUTPUTS = {
    "flat": (svg_anim.write, {}),
    "static colours": (svg_anim.write, {"color_tolerance": 255.0}),
    "merged": (svg_anim.write, {"color_tolerance": 255.0, "max_animations": 60}),
    "gouraud": (svg_gouraud.write, {"shading": "gouraud"}),
}
PAGE = ("<!doctype html><html><head><meta charset='utf-8'><style>html,body{margin:0}body{background:#000}"
        "svg{display:block}</style></head><body>%s</body></html>")
# Pause the page's <svg> at time t, then answer after two animation frames, so that the new time is painted.
SEEK = """const [t, done] = arguments, svg = document.querySelector('svg');
svg.pauseAnimations(); svg.setCurrentTime(t);
requestAnimationFrame(() => requestAnimationFrame(() => done(svg.getCurrentTime())));"""
BACKGROUND = """const [colour, done] = arguments; document.body.style.background = colour;
requestAnimationFrame(() => requestAnimationFrame(done));"""
WINDOW = (640, 640)  # room for a 512 px SVG or player and its controls


class Session:
    """One browser window: load a page, run a script, screenshot an element (subclasses speak the protocol)."""

    name = ""

    def __init__(self) -> None:
        self._dir = tempfile.TemporaryDirectory(prefix=f"facesvg-{self.name}-")
        self._pages = 0

    def load(self, html: str) -> None:
        """Open the page (written to a file: a large SVG is too long for a data: URL)."""
        self._pages += 1
        path = Path(self._dir.name) / f"page{self._pages}.html"
        path.write_text(html, encoding="utf-8")
        self.navigate(path.as_uri())

    def navigate(self, url: str) -> None:
        raise NotImplementedError

    def run(self, script: str, *args: Any) -> Any:
        """Run a script in the page (arguments as `arguments[i]`) and return its value."""
        raise NotImplementedError

    def run_async(self, script: str, *args: Any) -> Any:
        """Run a script whose last argument is a callback; return what it is called with."""
        raise NotImplementedError

    def png(self, css: str) -> bytes:
        """PNG screenshot of the first element matching a CSS selector."""
        raise NotImplementedError

    def close(self) -> None:
        self._dir.cleanup()

    def rgb(self, css: str) -> np.ndarray:
        """RGB uint8 (H, W, 3) screenshot of the element."""
        return np.asarray(Image.open(io.BytesIO(self.png(css))).convert("RGB"))

    def wait_for(self, expression: str, timeout: float = 60.0) -> None:
        """Poll a JS expression until it is truthy (TimeoutError after timeout seconds)."""
        script = f"""const done = arguments[arguments.length - 1], end = performance.now() + {timeout * 1000};
            (function poll() {{ if ({expression}) done(true); else if (performance.now() > end) done(false);
                               else setTimeout(poll, 50); }})();"""
        if not self.run_async(script):
            raise TimeoutError(f"{self.name}: {expression} still false after {timeout:.0f} s")


class Firefox(Session):
    """Headless Firefox over Marionette (a free port, a fresh profile, its log in the session's folder)."""

    name = "firefox"

    def __init__(self, exe: str) -> None:
        from marionette_driver.marionette import Marionette

        super().__init__()
        self.client = Marionette(bin=exe, app="fxdesktop", port=0, headless=True, startup_timeout=120,
                                 gecko_log=str(Path(self._dir.name) / "gecko.log"))
        try:
            self.client.start_session()
            self.client.timeout.script = 120
            self.client.set_window_rect(width=WINDOW[0], height=WINDOW[1])
        except BaseException:
            self.client.cleanup()
            raise

    def navigate(self, url: str) -> None:
        self.client.navigate(url)

    def run(self, script: str, *args: Any) -> Any:
        # sandbox=None runs in the page itself (as WebDriver does), so the page's own globals are visible.
        return self.client.execute_script(script, script_args=args, sandbox=None)

    def run_async(self, script: str, *args: Any) -> Any:
        return self.client.execute_async_script(script, script_args=args, sandbox=None)

    def png(self, css: str) -> bytes:
        from marionette_driver.by import By

        return self.client.screenshot(element=self.client.find_element(By.CSS_SELECTOR, css), format="binary")

    def close(self) -> None:
        try:
            self.client.cleanup()
        finally:
            self.client = None  # its profile's finaliser would clean up again at interpreter exit, and fail there
            super().close()


class WebKit(Session):
    """WebKitGTK's MiniBrowser in automation mode under WebKitWebDriver, on the X display given."""

    name = "webkit"

    def __init__(self, driver: str, minibrowser: str, display: str, env: dict[str, str] | None = None) -> None:
        from selenium import webdriver
        from selenium.webdriver.webkitgtk.service import Service

        super().__init__()
        options = webdriver.WebKitGTKOptions()
        options.binary_location = minibrowser
        options.add_argument("--automation")
        service = Service(executable_path=driver, service_args=["--host=127.0.0.1"],
                          env={**os.environ, **(env or {}), "DISPLAY": display},
                          log_output=str(Path(self._dir.name) / "webdriver.log"))
        self.driver = webdriver.WebKitGTK(options=options, service=service)
        try:
            self.driver.set_script_timeout(120)
            self.driver.set_window_rect(width=WINDOW[0], height=WINDOW[1])
        except BaseException:
            self.driver.quit()
            raise

    def navigate(self, url: str) -> None:
        self.driver.get(url)

    def run(self, script: str, *args: Any) -> Any:
        return self.driver.execute_script(script, *args)

    def run_async(self, script: str, *args: Any) -> Any:
        return self.driver.execute_async_script(script, *args)

    def png(self, css: str) -> bytes:
        # The element screenshot command answers an all-black image here (WebKitGTK 2.50, Xvfb, accelerated
        # compositing: it works with WEBKIT_DISABLE_COMPOSITING_MODE=1, a path real pages do not take), so the
        # element is cut out of the viewport screenshot, which is right.
        from selenium.webdriver.common.by import By

        rect = self.driver.find_element(By.CSS_SELECTOR, css).rect
        box = [round(rect[k]) for k in ("x", "y")]
        box += [box[0] + round(rect["width"]), box[1] + round(rect["height"])]
        out = io.BytesIO()
        Image.open(io.BytesIO(self.driver.get_screenshot_as_png())).crop(box).save(out, "PNG")
        return out.getvalue()

    def close(self) -> None:
        try:
            self.driver.quit()
        finally:
            super().close()


def firefox_path() -> str | None:
    """Debian's Firefox ESR, if installed."""
    return shutil.which("firefox-esr") or shutil.which("firefox")


def webkit_paths() -> tuple[str, str] | None:
    """WebKitWebDriver and the MiniBrowser it drives (Debian: /usr/lib/TRIPLET/webkit2gtk-4.1/), if installed."""
    driver = shutil.which("WebKitWebDriver")
    browsers = sorted(glob.glob("/usr/lib/*/webkit2gtk-4.*/MiniBrowser"))
    return (driver, browsers[-1]) if driver and browsers and shutil.which("Xvfb") else None


@contextlib.contextmanager
def xvfb(size: tuple[int, int] = (1280, 1024)) -> Iterator[str]:
    """An Xvfb server on a free display number for the length of the block; yields its DISPLAY (":N")."""
    read, write = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", f"{size[0]}x{size[1]}x24",
                             "-nolisten", "tcp"], pass_fds=(write,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    os.close(write)
    try:
        with os.fdopen(read) as pipe:
            number = pipe.readline().strip()  # Xvfb writes its display number once it accepts clients
        if not number:
            raise RuntimeError(f"Xvfb exited ({proc.wait()}) before it named a display")
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(10)


@contextlib.contextmanager
def launched_firefox(exe: str) -> Iterator[Firefox]:
    """A headless Firefox session for the length of the block (tests and bench)."""
    session = Firefox(exe)
    try:
        yield session
    finally:
        session.close()


@contextlib.contextmanager
def launched_webkit(driver: str, minibrowser: str, env: dict[str, str] | None = None) -> Iterator[WebKit]:
    """A WebKitGTK session on its own Xvfb display for the length of the block (tests and bench); env: variables
    its MiniBrowser gets besides ours (e.g. playback.WEBKIT_CPU_RASTER)."""
    with xvfb() as display:
        session = WebKit(driver, minibrowser, display, env)
        try:
            yield session
        finally:
            session.close()


def unblend(over_black: np.ndarray, over_white: np.ndarray) -> np.ndarray:
    """RGBA uint8 (straight alpha) from RGB shots of the same drawing over black and over white."""
    b, w = over_black.astype(np.float64), over_white.astype(np.float64)
    alpha = np.clip(255.0 - (w - b).mean(-1), 0.0, 255.0)
    rgb = np.where(alpha[..., None] > 0, b * 255.0 / np.maximum(alpha[..., None], 1e-9), 0.0)
    return np.dstack([np.clip(np.round(rgb), 0, 255), np.round(alpha)]).astype(np.uint8)


def svg_frames(session: Session, svg: bytes, times: Sequence[float], width: int, height: int) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of the SVG inlined in a page and paused at each time (one page load)."""
    session.load(PAGE % svg.decode("utf-8"))
    out = []
    for t in times:
        session.run_async(SEEK, float(t))
        shots = []
        for colour in ("#000", "#fff"):
            session.run_async(BACKGROUND, colour)
            shots.append(session.rgb("svg"))
        frame = unblend(*shots)
        if frame.shape[:2] != (height, width):
            raise AssertionError(f"{session.name} drew the SVG at {frame.shape[1]}x{frame.shape[0]}, "
                                 f"not {width}x{height} (device pixel ratio?)")
        out.append(frame)
    return np.stack(out)


def colour_difference(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute RGB difference in 8-bit levels where both RGBA frames are opaque (alpha > 127)."""
    both = (a[..., 3] > 127) & (b[..., 3] > 127)
    if not both.any():
        return 255.0
    return float(np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16))[both].mean())


def over_white(rgba: np.ndarray) -> np.ndarray:
    """RGB float of RGBA frames composited over white."""
    a = rgba[..., 3:4] / 255.0
    return rgba[..., :3] * a + 255.0 * (1 - a)


def distances(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N, M) mean RGB difference over white between each of N frames and each of M reference frames."""
    a, b = over_white(got), over_white(ref)
    return np.array([[float(np.abs(x - y).mean()) for y in b] for x in a])


def player_frames(session: Session, html: bytes, times: Sequence[float]) -> tuple[dict, np.ndarray]:
    """The player page's state ({state, renderer, error}) once it has loaded, and RGB shots of its canvas at each
    time (none when it shows an error)."""
    session.load(html.decode("utf-8"))
    session.wait_for("window.facesvgPlayer && window.facesvgPlayer.state !== 'loading'")
    state = session.run("const p = window.facesvgPlayer; return {state: p.state, renderer: p.renderer, "
                        "error: p.error};")
    shots = []
    if state["state"] == "ready":
        for t in times:
            session.run("facesvgPlayer.seek(arguments[0]);", float(t))
            session.run_async("const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(done));")
            shots.append(session.rgb("#facesvg-canvas"))
    return state, np.stack(shots) if shots else np.zeros((0, 0, 0, 3), np.uint8)
