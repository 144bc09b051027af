"""static/fap2d.html in headless Chromium draws the frames the Python reference renderer draws."""

from __future__ import annotations

import numpy as np
import pytest
import reference_render
from skimage.metrics import structural_similarity

from player import canvas_rgba, flatten, player_frame, player_page, player_values

# Same-frame SSIM threshold. What differs between the two renderers is only how triangle edges are
# anti-aliased (Skia's coverage-based clip vs the reference's pixel-centre rule) and Skia's bilinear filter vs
# scipy's. Measured: synthetic face 0.994-0.9997; bundled face (256 px) 0.997-0.9996 over the whole image and
# 0.984-0.998 in the mouth box, where lips move over the dark mouth layer. Wrong frames score 0.91 or less in
# the mouth box (synthetic: the neutral or half the jaw opening; bundled face: frame 55 shown for frame 60,
# 0.90; frame 0 for 60, 0.74), so 0.98 accepts the right frame and rejects a neighbouring one.
SSIM_SAME = 0.98


def ssim(a: np.ndarray, b: np.ndarray, box) -> float:
    """SSIM of two RGBA frames over a pixel box (x0, y0, x1, y1), composited on grey."""
    x0, y0, x1, y1 = box
    return float(structural_similarity(flatten(a)[y0:y1, x0:x1], flatten(b)[y0:y1, x0:x1], channel_axis=2,
                                       data_range=255))


def lower_face_box(pkg) -> tuple[int, int, int, int]:
    """The box around the mouth and chin, where the jaw moves the image."""
    fp = pkg.manifest["feature_points"]
    xs = [fp[k][0] for k in ("8.3", "8.4")]
    ys = [fp["2.2"][1], fp["2.1"][1]]
    w = xs[1] - xs[0] if xs[1] > xs[0] else xs[0] - xs[1]
    return (int(min(xs) - w / 2), int(min(ys) - w / 2), int(max(xs) + w / 2), int(max(ys) + w / 2))


@pytest.mark.browser
def test_player_draws_the_reference_frames(browser, synthetic_package, artifacts):
    data = synthetic_package[1]
    pkg = reference_render.load_package(data)
    box = lower_face_box(pkg)
    full = (0, 0, pkg.portrait.shape[1], pkg.portrait.shape[0])
    jaw = np.zeros(68)
    jaw[2] = 600
    half = jaw / 2
    with player_page(browser, data) as page:
        shown = player_values(page, jaw)
        ref = reference_render.render_frame(pkg, jaw)
        same = ssim(shown, ref, box)
        wrong = [ssim(shown, reference_render.render_frame(pkg, np.zeros(68)), box),
                 ssim(shown, reference_render.render_frame(pkg, half), box)]
        from PIL import Image

        Image.fromarray(np.concatenate([shown, ref], axis=1)).save(artifacts / "fap2d_player_vs_reference.png")
        assert same >= SSIM_SAME, f"jaw-open frame: SSIM {same:.4f}"
        assert max(wrong) < SSIM_SAME - 0.03, f"wrong frames score too high: {wrong}"
        for k in (0, pkg.n_frames // 2, pkg.n_frames - 1):
            score = ssim(player_frame(page, k), reference_render.render_stream_frame(pkg, k), full)
            assert score >= SSIM_SAME, f"stream frame {k}: SSIM {score:.4f}"


@pytest.mark.browser
def test_player_draws_the_sample_face_like_the_reference(browser, joy_package, artifacts):
    """The bundled face driven by joy.fap through the real engine: same frames in Chromium and in Python."""
    pkg = reference_render.load_package(joy_package)
    full = (0, 0, pkg.portrait.shape[1], pkg.portrait.shape[0])
    box = lower_face_box(pkg)
    with player_page(browser, joy_package) as page:
        scores = {}
        for k in (0, 30, 60, 90):
            shown = player_frame(page, k)
            ref = reference_render.render_stream_frame(pkg, k)
            scores[k] = (ssim(shown, ref, full), ssim(shown, ref, box))
        assert min(s[0] for s in scores.values()) >= SSIM_SAME, scores
        assert min(s[1] for s in scores.values()) >= SSIM_SAME, scores
        # A neighbouring frame is told apart: the check can fail.
        near = ssim(player_frame(page, 60), reference_render.render_stream_frame(pkg, 55), box)
        assert near < SSIM_SAME - 0.03, near


@pytest.mark.browser
def test_player_controls_play_pause_seek(browser, synthetic_package):
    with player_page(browser, synthetic_package[1], query="autoplay=0") as page:
        n = page.evaluate("() => window.fap2dPlayer.nFrames")
        assert n == synthetic_package[0].manifest["stream"]["frames"]
        assert page.input_value("#seek") == "0"
        page.click("#play")
        page.wait_for_function("() => window.fap2dPlayer.frame > 3", timeout=5000)
        assert page.text_content("#play") == "Pause"
        page.click("#play")
        stopped = page.evaluate("() => window.fap2dPlayer.frame")
        page.wait_for_timeout(300)
        assert page.evaluate("() => window.fap2dPlayer.frame") == stopped
        page.fill("#seek", "40")
        page.dispatch_event("#seek", "input")
        assert page.evaluate("() => window.fap2dPlayer.frame") == 40
        assert page.text_content("#frame") == f"41 / {n}"
        before = canvas_rgba(page)
        page.fill("#seek", "0")
        page.dispatch_event("#seek", "input")
        assert not np.array_equal(before, canvas_rgba(page))


@pytest.mark.browser
def test_player_reports_a_bad_package(browser):
    page = browser.new_page()
    try:
        from player import ORIGIN, STATIC

        def serve(route):
            path = route.request.url[len(ORIGIN):].split("?")[0]
            body = {"/static/fap2d.html": (STATIC / "fap2d.html").read_bytes(),
                    "/static/fap2d.js": (STATIC / "fap2d.js").read_bytes()}.get(path, b"this is not a zip")
            route.fulfill(status=200, body=body)

        page.route(ORIGIN + "/**", serve)
        page.goto(f"{ORIGIN}/static/fap2d.html?src=/bad.zip")
        page.wait_for_function("() => document.getElementById('status').textContent.startsWith('Cannot')")
        assert "not a zip" in page.text_content("#status")
        assert page.is_disabled("#play")
    finally:
        page.close()
