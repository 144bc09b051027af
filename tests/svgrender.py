"""Rasterise an SVG at a chosen animation time in headless Chromium (Playwright), for end-to-end tests."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image


def chromium_frame(browser, svg: bytes, t: float, width: int, height: int, scale: float = 1.0) -> np.ndarray:
    """RGBA uint8 (H, W, 4) of the SVG paused at time t seconds (transparent background)."""
    page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=scale)
    try:
        html = (
            "<!doctype html><html><body style='margin:0;background:transparent'>"
            + svg.decode("utf-8")
            + "</body></html>"
        )
        page.set_content(html)
        page.evaluate(
            """(t) => { const s = document.querySelector('svg');
                s.pauseAnimations(); s.setCurrentTime(t); }""",
            t,
        )
        page.wait_for_timeout(50)
        png = page.locator("svg").screenshot(omit_background=True, animations="allow")
    finally:
        page.close()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))


def chromium_frames(browser, svg: bytes, times: list[float], width: int, height: int) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of the SVG paused at each time, from one page (a large SVG is parsed once)."""
    page = browser.new_page(viewport={"width": width, "height": height})
    try:
        page.set_content("<!doctype html><html><body style='margin:0;background:transparent'>"
                         + svg.decode("utf-8") + "</body></html>")
        out = []
        for t in times:
            page.evaluate(
                "(t) => { const s = document.querySelector('svg'); s.pauseAnimations(); s.setCurrentTime(t); }", t
            )
            page.wait_for_timeout(50)
            png = page.locator("svg").screenshot(omit_background=True, animations="allow")
            out.append(np.asarray(Image.open(io.BytesIO(png)).convert("RGBA")))
    finally:
        page.close()
    return np.stack(out)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0
