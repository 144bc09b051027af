"""three.js as the independent reference: it plays the same glTF in headless Chromium with the camera of our SVG.

The page (player.html + player.js) loads three.js from node_modules (`npm ci` in this folder); Playwright serves
it and the glTF's folder from disk by request interception, so no server or port is involved. Our SVG is
rasterised in the same Chromium at the same times (tests/svgrender.py), or our player (--to player) drawn by its
own script and read off its canvas, and the two are compared per frame: silhouette IoU, and the mean colour
difference inside both silhouettes where the colours are comparable.
"""

from __future__ import annotations

import base64
import io
import json
import mimetypes
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree
from PIL import Image
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from converter.formats.gltf import parse_container
from converter.writers import player as player_writer
from tests.svgrender import chromium_frames, iou

HERE = Path(__file__).resolve().parent
THREE = HERE / "node_modules" / "three" / "package.json"
ORIGIN = "http://reference.invalid"  # never resolved: every request under it is answered from disk
ALPHA = 127  # a pixel belongs to a silhouette above this alpha
SVG_NS = "{http://www.w3.org/2000/svg}"

Clips = str | Sequence[int | str]  # "all", or animation indices / names as three.js's gltf.animations holds them


def missing() -> str | None:
    """Why the reference cannot run here (no node/npm, or `npm ci` not run), or None."""
    if not THREE.exists():
        if shutil.which("npm") is None:
            return "node/npm not installed (apt-get install nodejs npm), so three.js is missing"
        return f"three.js not installed: run `npm ci` in {HERE}"
    return None


def three_version() -> str:
    """The installed three.js version."""
    return json.loads(THREE.read_text())["version"]


def svg_metadata(svg: bytes) -> dict:
    """The <metadata id="facesvg"> JSON of one of our SVGs, or of our player file (its metadata block)."""
    if player_writer.is_player(svg):
        return player_writer._blocks(svg)[0]
    root = etree.fromstring(svg, etree.XMLParser(huge_tree=True))
    node = root.find(f".//{SVG_NS}metadata[@id='facesvg']")
    if node is None:
        raise ValueError("the SVG has no facesvg metadata")
    return json.loads(node.text)


def frame_times(meta: dict, frames: Sequence[int]) -> list[float]:
    """Animation time of each of our frame indices (frame k of the file is source frame start + k)."""
    start = meta.get("source_frames", [0])[0]
    return [(start + k) / meta["fps"] for k in frames]


def spread_frames(n_frames: int, count: int = 5) -> list[int]:
    """count frame indices spread over 0..n_frames-1, first and last included; the inner ones sit 0.37 of a
    step early so they do not all land on the even subdivisions where exporters put clip boundaries."""
    inner = (np.arange(1, count - 1) - 0.37) / max(count - 1, 1)
    return sorted({int(round(x * (n_frames - 1))) for x in np.r_[0.0, inner, 1.0][:max(count, 1)]})


def _fulfil(roots: dict[str, Path], missing: list[str]):
    def handle(route) -> None:
        path = route.request.url[len(ORIGIN):].split("?", 1)[0]
        prefix, _, rest = path.lstrip("/").partition("/")
        base = roots.get(prefix)
        # normpath, not resolve: node_modules may be a symlink; ".." still cannot climb out of the root
        target = Path(os.path.normpath(base / rest)) if base else None
        if target is None or base not in target.parents or not target.is_file():
            missing.append(path)
            route.fulfill(status=404, body="not found")
            return
        kind = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
        if target.suffix in (".js", ".mjs"):
            kind = "text/javascript"
        route.fulfill(status=200, body=target.read_bytes(), content_type=kind)

    return handle


def threejs_frames(browser, gltf: Path, meta: dict, frames: Sequence[int], clips: Clips = "all",
                   linear: bool = False, camera: dict | None = None) -> tuple[np.ndarray, dict]:
    """RGBA uint8 (N, H, W, 4) three.js renders of gltf at our frames (flat Lambert in our light rig), and info.

    camera defaults to meta["camera"]; linear=True writes shaded colours without the sRGB output transform.
    info holds the three.js revision, every clip's name and the clips played."""
    cam = camera or meta["camera"]
    width, height = cam["viewport"]
    gltf = Path(gltf).resolve()
    page = browser.new_page(viewport={"width": width, "height": height})
    errors: list[str] = []
    missing_files: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        page.route(f"{ORIGIN}/**", _fulfil({"ref": HERE, "data": gltf.parent}, missing_files))
        page.goto(f"{ORIGIN}/ref/player.html")
        try:
            page.wait_for_function("window.referencePlayer !== undefined", timeout=60000)
        except PlaywrightTimeout:
            raise RuntimeError(
                f"the reference page did not start (errors {errors}, not found {missing_files})"
            ) from None
        req = {"url": f"{ORIGIN}/data/{gltf.name}", "clips": clips if clips == "all" else list(clips),
               "view": cam["view"], "projection": cam["projection"], "viewport": [width, height],
               "times": frame_times(meta, frames), "linear": linear}
        result = page.evaluate("(req) => window.referencePlayer.render(req)", req)
    finally:
        page.close()
    if errors:
        raise RuntimeError(f"the reference page failed: {errors}")
    raw = [np.frombuffer(base64.b64decode(f), np.uint8).reshape(height, width, 4)[::-1] for f in result["frames"]]
    return np.stack(raw), {"revision": result["revision"], "clips": result["clips"], "played": result["played"]}


def svg_frames(browser, svg: bytes, frames: Sequence[int]) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of our SVG in Chromium, paused at each frame's time (SMIL setCurrentTime)."""
    meta = svg_metadata(svg)
    width, height = meta["viewport"]
    return chromium_frames(browser, svg, [k / meta["fps"] for k in frames], width, height)


def player_frames(browser, html: bytes, frames: Sequence[int], renderer: str | None = None) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of our player file's canvas at each frame (seeked to k / fps), multisampled
    throughout (as tests/writers/test_player.py opens it: pixels do not depend on the machine's speed), starting
    from renderer ("webgl2", "webgl" or "canvas2d") when given; the page behind the canvas left transparent."""
    meta = svg_metadata(html)
    width, height = meta["viewport"]
    ctx = browser.new_context(viewport={"width": width + 64, "height": height + 128})
    ctx.add_init_script(f"window.facesvgPlayerOptions = {json.dumps({'renderer': renderer, 'antialias': True})}")
    page = ctx.new_page()
    try:
        page.set_content(html.decode())
        page.wait_for_function("() => window.facesvgPlayer && facesvgPlayer.state !== 'loading'", timeout=60_000)
        state, drawn = page.evaluate("() => [facesvgPlayer.state, facesvgPlayer.renderer]")
        if state != "ready" or (renderer and drawn != renderer):
            raise RuntimeError(f"the player did not start with {renderer or 'its first renderer'}: {state}, {drawn}")
        out = []
        for k in frames:
            page.evaluate("(t) => facesvgPlayer.seek(t)", k / meta["fps"])
            png = page.locator("#facesvg-canvas").screenshot(omit_background=True)
            out.append(np.asarray(Image.open(io.BytesIO(png)).convert("RGBA")))
    finally:
        ctx.close()
    return np.stack(out)


def colours_comparable(gltf: Path) -> bool:
    """True when every drawn primitive's colour is vertex colours or a baseColorFactor, with no texture.

    (The player draws no textures, so a textured primitive's colours are not compared.)"""
    doc, _ = parse_container(Path(gltf).read_bytes())
    materials = doc.get("materials") or []
    for mesh in doc.get("meshes") or []:
        for prim in mesh.get("primitives") or []:
            if prim.get("mode", 4) not in (4, 5, 6):
                continue
            mat = materials[prim["material"]] if prim.get("material") is not None else {}
            pbr = mat.get("pbrMetallicRoughness") or {}
            if pbr.get("baseColorTexture") is not None:
                return False
            if pbr.get("baseColorFactor") is None and "COLOR_0" not in (prim.get("attributes") or {}):
                return False
    return True


@dataclass
class Comparison:
    """Per compared frame: silhouette IoU, and mean |RGB| difference (0..255) inside both masks or None."""

    frames: list[int]
    iou: list[float]
    colour: list[float | None]
    clips: list[str]
    played: list[str]
    images: tuple[np.ndarray, np.ndarray]  # (ours, three.js) RGBA stacks, for artifacts

    @property
    def min_iou(self) -> float:
        """The worst frame's IoU."""
        return min(self.iou)


def compare(browser, gltf: Path, svg: bytes, frames: Sequence[int], clips: Clips = "all",
            linear: bool = False, camera: dict | None = None, renderer: str | None = None) -> Comparison:
    """Our SVG (or player file, drawn from renderer on) against three.js playing gltf (clips) at our frames;
    colours only where comparable.

    Colours compare as displayed (three.js's sRGB output transform, the default): we read glTF's linear colours,
    light them in linear light and encode them once, as three.js does. linear=True compares three.js's shaded
    colours before that transform instead (they then differ from ours by the sRGB curve)."""
    meta = svg_metadata(svg)
    if player_writer.is_player(svg):
        ours = player_frames(browser, svg, frames, renderer)
    else:
        ours = svg_frames(browser, svg, frames)
    ref, info = threejs_frames(browser, gltf, meta, frames, clips, linear, camera)
    with_colour = colours_comparable(gltf)
    ious, colours = [], []
    for a, b in zip(ours, ref):
        ma, mb = a[..., 3] > ALPHA, b[..., 3] > ALPHA
        ious.append(iou(ma, mb))
        both = ma & mb
        if with_colour and both.any():
            colours.append(float(np.abs(a[..., :3].astype(int) - b[..., :3].astype(int))[both].mean()))
        else:
            colours.append(None)
    return Comparison(list(frames), ious, colours, info["clips"], info["played"], (ours, ref))


def side_by_side(comparison: Comparison) -> np.ndarray:
    """One RGBA image: our frames on the top row, three.js's below, over mid grey."""
    ours, ref = comparison.images
    rows = []
    for stack in (ours, ref):
        row = np.concatenate(list(stack), axis=1).astype(float)
        a = row[..., 3:] / 255
        rows.append(np.concatenate([row[..., :3] * a + 128 * (1 - a), np.full_like(a, 255)], -1))
    return np.concatenate(rows, axis=0).astype(np.uint8)
