"""The puppet player in headless Chromium draws what the 3D face draws: silhouettes against our prerender.

The reference is converter/render.py (pyrender on Mesa EGL) of blendshapes.drive's frames with the puppet's own
camera; the puppet is the HTML file writers/puppet.py writes, read back from the canvas. The script's evaluator is
also held to the Python one (converter.puppet.pose), vertex by vertex.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import math
import re
import socket
import threading
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from converter import blendshapes, render
from converter.formats.captures.base import WeightTrack
from converter.formats.morphs import load_morph_face
from converter.options import ConversionOptions, Report
from converter.puppet import from_track, pose, puppet_of, resolve, shade
from converter.puppet.take import frame_pose, frame_times
from converter.writers import puppet as writer

IOU_MIN = 0.98  # the target, head angles within +-20 degrees
JS_PX = 0.01  # the script's float32 arrays against the Python evaluator's float64
SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "face.glb"


def synthetic_take(names: list[str], n: int = 12, fps: float = 30.0, eyes: bool = True) -> WeightTrack:
    """n frames: each weight a different wave 0..1, head yaw/pitch within +-20 degrees, roll within +-0.2 rad."""
    t = np.arange(n) / fps
    phase = np.linspace(0, 1, n)
    values = np.stack([0.5 - 0.5 * np.cos(2 * np.pi * (phase * (1 + 0.3 * k) + 0.17 * k)) for k in range(len(names))],
                      axis=1).astype(np.float32)
    head = np.stack([np.radians(20) * np.sin(2 * np.pi * phase), np.radians(-15) * np.sin(4 * np.pi * phase + 1),
                     0.2 * np.sin(2 * np.pi * phase + 2)], axis=1).astype(np.float32)
    eye = np.stack([np.radians(15) * np.cos(2 * np.pi * phase), np.radians(10) * np.sin(2 * np.pi * phase),
                    np.zeros(n)], axis=1).astype(np.float32)
    return WeightTrack(list(names), t, values, fps, head=head, eye_left=eye if eyes else None,
                       eye_right=eye if eyes else None)


def quantised(track: WeightTrack, take) -> WeightTrack:
    """The track as the take stores it (what the player plays), for driving the 3D face."""
    rows = [frame_pose(take, k) for k in range(take.n_frames)]
    w = np.array([r[0] for r in rows], np.float32)
    head = np.array([r[1] for r in rows], np.float32) if take.head is not None else None
    eyes = np.array([r[2] for r in rows], np.float32) if take.eyes is not None else None
    left = None if eyes is None else np.c_[eyes[:, :2], np.zeros(len(eyes))].astype(np.float32)
    right = None if eyes is None else np.c_[eyes[:, 2:], np.zeros(len(eyes))].astype(np.float32)
    return WeightTrack(track.names, track.times, w, track.fps, head=head, eye_left=left, eye_right=right)


# The WebGL drawing buffer is not preserved once composited: draw and read in one task.
SNAPSHOT = "() => { puppet.render(); return document.getElementById('puppet-canvas').toDataURL('image/png'); }"


def canvas_alpha(page) -> np.ndarray:
    """The puppet canvas's alpha (H, W) uint8, drawn again and read at once."""
    url = page.evaluate(SNAPSHOT)
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA"))[..., 3]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    return float((a & b).sum() / max((a | b).sum(), 1))


def reference_alpha(face, puppet, track: WeightTrack, frames: list[int]) -> dict[int, np.ndarray]:
    """The prerender's alpha of the 3D face driven by the track, at frames, with the puppet's camera."""
    anim = blendshapes.drive(face, track)
    rgb = np.ones((anim.n_frames, anim.n_vertices, 3), np.float32)
    shots = render.render_frames(anim.frames, anim.faces, rgb, puppet.camera, frames)
    return {k: v[..., 3] for k, v in shots.items()}


def open_puppet(browser, tmp_path: Path, page_bytes: bytes, query: str = "?paused"):
    """A Chromium page on the puppet file, ready, paused."""
    path = tmp_path / "puppet.html"
    path.write_bytes(page_bytes)
    size = 1024
    page = browser.new_page(viewport={"width": size, "height": size})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(path.as_uri() + query)
    page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=60000)
    assert page.evaluate("() => document.documentElement.dataset.puppet") == "ready", errors
    page.evaluate("() => puppet.pause()")
    return page


def js_positions(page) -> tuple[np.ndarray, np.ndarray]:
    """The script's evaluated (V, 2) px and (V,) depth."""
    got = page.evaluate("() => puppet.positions()")
    return np.array(got["xy"], np.float64).reshape(-1, 2), np.array(got["z"], np.float64)


def check_take(browser, tmp_path, face, names, renderer: str, artifacts: Path, label: str) -> list[float]:
    """Play a synthetic take embedded in the puppet: the script's vertices equal the Python evaluator's and its
    silhouettes match the 3D prerender's; returns the IoUs."""
    puppet = puppet_of(face, ConversionOptions(size=256))
    track = synthetic_take(names, eyes=bool(puppet.eyes))
    take = from_track(track)
    page_bytes = writer.write(puppet.with_take(take), ConversionOptions(), Report())
    frames = [0, 3, 6, 9, 11]
    refs = reference_alpha(face, puppet, quantised(track, take), sorted({*frames, *(k + 1 for k in frames[:-1])}))
    mapping = resolve(puppet, take.names)
    times = frame_times(take)
    page = open_puppet(browser, tmp_path, page_bytes, "?paused" + ("&renderer=canvas" if renderer == "canvas" else ""))
    scores = []
    try:
        assert page.evaluate("() => puppet.renderer") == renderer or renderer == "webgl"
        for k in frames:
            page.evaluate("(t) => puppet.seek(t)", float(times[k]) + 1e-9)
            w, head, eyes = frame_pose(take, k)
            want_xy, want_z = pose(puppet, w @ mapping, head=head, eyes=eyes)
            got_xy, got_z = js_positions(page)
            assert np.abs(got_xy - want_xy).max() <= JS_PX, f"frame {k}"
            assert np.abs(got_z - want_z).max() <= 1e-5
            shown = canvas_alpha(page) > 127
            ref = refs[k] > 127
            scores.append(iou(shown, ref))
            if k + 1 in refs:  # the right frame, not a neighbour, is what fits best
                assert scores[-1] > iou(shown, refs[k + 1] > 127), f"frame {k}"
            Image.fromarray(np.concatenate([shown, ref], axis=1).astype(np.uint8) * 255).save(
                artifacts / f"puppet_{label}_{renderer}_{k}.png")
    finally:
        page.close()
    assert min(scores) >= IOU_MIN, scores
    return scores


@pytest.mark.browser
@pytest.mark.parametrize("renderer", ["webgl", "canvas"])
def test_generated_face_take_matches_the_3d_render(browser, tmp_path, face, renderer, artifacts):
    check_take(browser, tmp_path, face, list(face.names), renderer, artifacts, "generated")


@pytest.mark.browser
def test_bundled_sample_take_matches_the_3d_render(browser, tmp_path, artifacts):
    face = load_morph_face(SAMPLE)
    assert face.names  # the sample has named morph targets (ARKit-style, ICT's _L/_R spelling)
    check_take(browser, tmp_path, face, list(face.names), "webgl", artifacts, "sample")


@pytest.mark.browser
def test_set_moves_the_face_and_matches_the_3d_render(browser, tmp_path, face, artifacts):
    puppet = puppet_of(face, ConversionOptions(size=256))
    page = open_puppet(browser, tmp_path, writer.write(puppet, ConversionOptions(), Report()))
    try:
        assert page.evaluate("() => puppet.duration") == 0  # no take embedded
        page.evaluate("() => puppet.set({jawOpen: 0}).render()")
        rest = canvas_alpha(page) > 127
        head = [math.radians(12), math.radians(-8), 0.1]
        # ARKit's spelling, another spelling of a target name, and the head's own parameter names
        page.evaluate("(h) => puppet.set({JawOpen: 1, mouth_smile_left: 0.5, headYaw: h[0], headPitch: h[1], "
                      "headRoll: h[2]}).render()", head)
        moved = canvas_alpha(page) > 127
        weights = page.evaluate("() => puppet.weights()")
        got_xy, _ = js_positions(page)
    finally:
        page.close()
    assert weights["jawOpen"] == 1 and abs(weights["mouthSmileLeft"] - 0.5) < 1e-6
    assert (moved != rest).sum() > 200  # the face moved
    track = WeightTrack(["jawOpen", "mouthSmileLeft"], np.zeros(1), np.array([[1.0, 0.5]], np.float32), 30.0,
                        head=np.array([head], np.float32))
    ref = reference_alpha(face, puppet, track, [0])[0] > 127
    assert iou(moved, ref) >= IOU_MIN
    want, _ = pose(puppet, np.array([weights[p.name] for p in puppet.morphs]), head=tuple(head))
    assert np.abs(got_xy - want).max() <= JS_PX


class OneMessageServer:
    """A WebSocket server on loopback (RFC 6455 handshake, one unmasked text frame) that sends a message to the
    first client, then holds the connection open until closed."""

    GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11"

    def __init__(self, message: str) -> None:
        self.message = message.encode()
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(1)
        self.port = self.sock.getsockname()[1]
        self.conn = None
        self.thread = threading.Thread(target=self.serve, daemon=True)
        self.thread.start()

    def serve(self) -> None:
        conn, _ = self.sock.accept()
        self.conn = conn
        request = b""
        while b"\r\n\r\n" not in request:
            request += conn.recv(4096)
        key = re_search(rb"Sec-WebSocket-Key: *([^\r\n]+)", request)
        accept = base64.b64encode(hashlib.sha1(key + self.GUID.encode()).digest())
        conn.sendall(b"HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                     b"Sec-WebSocket-Accept: " + accept + b"\r\n\r\n")
        n = len(self.message)
        head = bytes([0x81, n]) if n < 126 else bytes([0x81, 126]) + n.to_bytes(2, "big")
        conn.sendall(head + self.message)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.sock.close()


def re_search(pattern: bytes, data: bytes) -> bytes:
    """The first group of a regex match (the handshake's key)."""
    m = re.search(pattern, data, re.I)
    assert m, data
    return m.group(1).strip()


@pytest.mark.browser
def test_a_live_websocket_message_drives_the_puppet(browser, tmp_path, face):
    puppet = puppet_of(face, ConversionOptions(size=256))
    head = [0.25, -0.1, 0.05]
    server = OneMessageServer(json.dumps({"weights": {"JawOpen": 0.75, "browInnerUp": 0.5}, "head": head}))
    try:
        page = open_puppet(browser, tmp_path, writer.write(puppet, ConversionOptions(), Report()),
                           f"?live=ws://127.0.0.1:{server.port}")
        try:
            page.wait_for_function("() => puppet.weights().jawOpen === 0.75", timeout=30000)
            page.evaluate("() => puppet.render()")
            got, _ = js_positions(page)
            weights = page.evaluate("() => puppet.weights()")
        finally:
            page.close()
    finally:
        server.close()
    want, _ = pose(puppet, np.array([weights[p.name] for p in puppet.morphs]), head=tuple(head))
    assert weights["browInnerUp"] == 0.5
    assert np.abs(got - want).max() <= JS_PX
    assert np.abs(got - puppet.xy).max() > 10


def canvas_rgb(page) -> np.ndarray:
    """The puppet canvas's RGB (H, W, 3) uint8, drawn again and read at once."""
    url = page.evaluate(SNAPSHOT)
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")).astype(int)


@pytest.mark.browser
@pytest.mark.parametrize("renderer", ["webgl", "canvas"])
def test_the_player_relights_the_turned_head(browser, tmp_path, face, renderer):
    """Each big front triangle of the flat puppet with the head turned is drawn in model.shade's colour (the rest
    normals turned and lit as converter/lighting.py lights them), not the colour baked at rest."""
    puppet = puppet_of(face, ConversionOptions(size=256))
    head = (math.radians(20), math.radians(-15), 0.2)
    xy, _ = pose(puppet, np.zeros(len(puppet.morphs)), head=head)
    want, rest = shade(puppet, head).astype(int), puppet.colors.astype(int)
    corners = xy[puppet.triangles]
    area = -0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    changed = np.abs(want - rest).max(axis=1) >= 8
    picks = np.flatnonzero(changed & (area > 0))
    picks = picks[np.argsort(-area[picks])][:12]
    assert len(picks) >= 6
    query = "?paused" + ("&renderer=canvas" if renderer == "canvas" else "")
    page = open_puppet(browser, tmp_path, writer.write(puppet, ConversionOptions(), Report()), query)
    try:
        page.evaluate("(h) => puppet.set({headYaw: h[0], headPitch: h[1], headRoll: h[2]}).render()", list(head))
        image = canvas_rgb(page)
    finally:
        page.close()
    centre = np.rint(corners[picks].mean(axis=1) - 0.5).astype(int)
    got = image[centre[:, 1], centre[:, 0]]
    close = np.abs(got - want[picks]).max(axis=1) <= 3  # a centre may fall on a nearer triangle: most must match
    assert close.mean() >= 0.75, (got, want[picks])
    assert (np.abs(got - rest[picks]).max(axis=1) > 3).mean() >= 0.75


@pytest.mark.browser
@pytest.mark.parametrize("version", [writer.VERSION + 1, 2])
def test_the_player_refuses_a_format_it_does_not_know(browser, tmp_path, puppet, version):
    """A package of another format version is refused with a clear message, not drawn wrong."""
    data = writer.write(puppet, ConversionOptions(), Report())
    meta = f'"version":{writer.VERSION}'.encode()
    assert data.count(meta) == 1
    path = tmp_path / "puppet.html"
    path.write_bytes(data.replace(meta, f'"version":{version}'.encode()))
    page = browser.new_page()
    try:
        page.goto(path.as_uri() + "?paused")
        page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=60000)
        assert page.evaluate("() => document.documentElement.dataset.puppet") == "failed"
        status = page.evaluate("() => document.getElementById('puppet-status').textContent")
        assert f"format facesvg-puppet {version}" in status and "does not know" in status
    finally:
        page.close()


def canvas_rgba(page) -> np.ndarray:
    """The puppet canvas's RGBA (H, W, 4), drawn again and read at once."""
    url = page.evaluate(SNAPSHOT)
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA")).astype(int)


@pytest.mark.browser
@pytest.mark.parametrize("shading", ["flat", "gouraud"])
def test_webgl_draws_what_the_script_raster_draws(browser, tmp_path, face, shading):
    """WebGL2 (the head turned in the vertex shader, indexed, a flat triangle's colour from a last corner of its own)
    and the canvas fallback (all of it in script, as GL rasterises) colour the same pixels alike, in a pose with
    weights, the head and both eyes turned."""
    puppet = puppet_of(face, ConversionOptions(size=256, shading=shading))
    data = writer.write(puppet, ConversionOptions(), Report())
    pose_values = {"jawOpen": 0.7, "mouthSmileLeft": 0.4, "eyeBlinkLeft": 0.3, "headYaw": 0.3, "headPitch": -0.2,
                   "headRoll": 0.15, "eyeYawLeft": 0.25, "eyePitchLeft": -0.1, "eyeYawRight": -0.2,
                   "eyePitchRight": 0.15}
    shots, xy = {}, {}
    for renderer in ("webgl2", "canvas"):
        page = open_puppet(browser, tmp_path, data, "?paused" + ("&renderer=canvas" if renderer == "canvas" else ""))
        try:
            assert page.evaluate("() => puppet.renderer") == renderer
            page.evaluate("(v) => { puppet.set(v); }", pose_values)
            shots[renderer] = canvas_rgba(page)
            xy[renderer], _ = js_positions(page)
        finally:
            page.close()
    gl, cv = shots["webgl2"], shots["canvas"]
    assert np.abs(xy["webgl2"] - xy["canvas"]).max() == 0  # one evaluator
    drawn_gl, drawn_cv = gl[..., 3] > 127, cv[..., 3] > 127
    assert drawn_gl.sum() > 5000 and iou(drawn_gl, drawn_cv) >= 0.995
    both = drawn_gl & drawn_cv
    alike = (np.abs(gl[..., :3] - cv[..., :3]).max(axis=-1) <= 2)[both]
    assert alike.mean() >= 0.98, alike.mean()


CONTROLS = "() => ['puppet-controls', 'puppet-live-row', 'puppet-sliders'].map((id) => " \
           "document.getElementById(id).getBoundingClientRect().height > 0)"


@pytest.mark.browser
def test_embed_mode_hides_the_play_and_live_controls(browser, tmp_path, puppet):
    """?embed, or a frame carrying data-puppet-embed (the web app's /live page), hides the player's own Play and
    Live rows; the sliders and the API stay."""
    data = writer.write(puppet, ConversionOptions(), Report())
    for query, shown in (("?paused", [True, True, True]), ("?paused&embed", [False, False, True])):
        page = open_puppet(browser, tmp_path, data, query)
        try:
            assert page.evaluate(CONTROLS) == shown, query
        finally:
            page.close()
    host = ('<!doctype html><iframe id="a" src="/puppet.html?paused" data-puppet-embed width="900" height="700">'
            '</iframe><iframe id="b" src="/puppet.html?paused" width="900" height="700"></iframe>')
    page = browser.new_page(viewport={"width": 1000, "height": 1600})
    try:
        page.route("http://puppet.test/**", lambda route: route.fulfill(
            body=data if route.request.url.split("?")[0].endswith("/puppet.html") else host.encode(),
            content_type="text/html"))
        page.goto("http://puppet.test/host.html")
        got = {}
        for name in "ab":
            frame = page.locator(f"#{name}").element_handle().content_frame()
            frame.wait_for_function("() => document.documentElement.dataset.puppet === 'ready'", timeout=60000)
            got[name] = frame.evaluate(CONTROLS)
    finally:
        page.close()
    assert got == {"a": [False, False, True], "b": [True, True, True]}
