"""Drive static/fap2d.html in headless Chromium (Playwright), serving the page and a package from memory."""

from __future__ import annotations

import base64
import io
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

STATIC = Path(__file__).resolve().parents[2] / "static"
ORIGIN = "http://fap2d.test"


@contextmanager
def player_page(browser, package: bytes, query: str = "frame=0"):
    """A page with the player loaded on the package (paused at frame 0); yields the Playwright page."""
    size = 1024
    page = browser.new_page(viewport={"width": size, "height": size})
    files = {
        "/static/fap2d.html": (STATIC / "fap2d.html").read_bytes(),
        "/static/fap2d.js": (STATIC / "fap2d.js").read_bytes(),
        "/pkg.zip": package,
    }
    types = {".html": "text/html", ".js": "text/javascript", ".zip": "application/zip"}

    def serve(route):
        path = route.request.url[len(ORIGIN):].split("?")[0]
        if path in files:
            route.fulfill(status=200, body=files[path], content_type=types[Path(path).suffix])
        else:
            route.fulfill(status=404, body=b"not found")

    page.route(ORIGIN + "/**", serve)
    try:
        page.goto(f"{ORIGIN}/static/fap2d.html?src=/pkg.zip&{query}")
        page.wait_for_function("() => window.fap2dPlayer !== undefined || "
                               "document.getElementById('status').textContent.startsWith('Cannot')", timeout=30000)
        page.evaluate("() => window.fap2dReady.then(() => true)")
        yield page
    finally:
        page.close()


def canvas_rgba(page) -> np.ndarray:
    """The player canvas as (H, W, 4) uint8."""
    url = page.evaluate("() => document.getElementById('face').toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA"))


def player_frame(page, k: int) -> np.ndarray:
    """Frame k of the package's stream as the player draws it."""
    page.evaluate("(k) => window.fap2dPlayer.renderFrame(k)", k)
    return canvas_rgba(page)


def player_values(page, values) -> np.ndarray:
    """The player's drawing for one row of 68 FAP values."""
    page.evaluate("(v) => window.fap2dPlayer.renderValues(Float32Array.from(v))", [float(x) for x in values])
    return canvas_rgba(page)


def flatten(rgba: np.ndarray, background=(128, 128, 128)) -> np.ndarray:
    """RGB float image of RGBA composited over a plain background."""
    a = rgba[..., 3:4].astype(np.float64) / 255
    return rgba[..., :3].astype(np.float64) * a + np.array(background, np.float64) * (1 - a)
