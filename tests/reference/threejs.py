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
import math
import mimetypes
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from lxml import etree
from PIL import Image
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from skimage.metrics import structural_similarity

from converter import blendshapes, render
from converter.blendshapes import rotations
from converter.extract import unit_vertex_normals
from converter.formats.captures.base import WeightTrack
from converter.formats.gltf import parse_container
from converter.lighting import DEFAULT_LIGHTING, lambert_linear, srgb_to_linear
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


def require() -> None:
    """Skip the calling test where three.js cannot run (missing()); fail instead when CI is set (`make setup` runs
    npm ci)."""
    why = missing()
    if why:
        if os.environ.get("CI"):
            pytest.fail(f"{why}, but CI is set: `make setup` must run npm ci")
        pytest.skip(why)


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


def _reference_run(browser, gltf: Path, width: int, height: int, script: str, req: dict) -> dict:
    """script(req)'s answer in the three.js reference page (tests/reference/player.html) serving gltf's folder."""
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
        result = page.evaluate(script, req)
    finally:
        page.close()
    if errors:
        raise RuntimeError(f"the reference page failed: {errors} (not found {missing_files})")
    return result


def threejs_frames(browser, gltf: Path, meta: dict, frames: Sequence[int], clips: Clips = "all",
                   linear: bool = False, camera: dict | None = None) -> tuple[np.ndarray, dict]:
    """RGBA uint8 (N, H, W, 4) three.js renders of gltf at our frames (flat Lambert in our light rig), and info.

    camera defaults to meta["camera"]; linear=True writes shaded colours without the sRGB output transform.
    info holds the three.js revision, every clip's name and the clips played."""
    cam = camera or meta["camera"]
    width, height = cam["viewport"]
    gltf = Path(gltf).resolve()
    req = {"url": f"{ORIGIN}/data/{gltf.name}", "clips": clips if clips == "all" else list(clips),
           "view": cam["view"], "projection": cam["projection"], "viewport": [width, height],
           "times": frame_times(meta, frames), "linear": linear}
    result = _reference_run(browser, gltf, width, height, "(req) => window.referencePlayer.render(req)", req)
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


# --- Posed renders (tests/puppet/test_threejs.py, bench/bench_puppet.py): the same morph weights and head turn in
# three.js, in the puppet player and in our 3D prerender, compared by silhouette IoU and luminance SSIM.

# Evaluated in player.html, whose import map resolves 'three': load the glTF once, then per pose set every mesh's
# morphTargetInfluences by target name and the scene's matrix (the head turn about the puppet's pivot), and render.
POSE_JS = """async (req) => {
  const THREE = await import('three');
  const { GLTFLoader } = await import('three/addons/loaders/GLTFLoader.js');
  const { MeshoptDecoder } = await import('three/addons/libs/meshopt_decoder.module.js');
  const gltf = await new GLTFLoader().setMeshoptDecoder(MeshoptDecoder).loadAsync(req.url);
  const rowMajor = (rows) => new THREE.Matrix4().set(...rows.flat());
  const scene = new THREE.Scene();
  const turn = new THREE.Group();
  turn.matrixAutoUpdate = false;
  turn.add(gltf.scene);
  scene.add(turn);
  const meshes = [];
  gltf.scene.traverse((obj) => {
    obj.frustumCulled = false;
    if (!obj.isMesh) return;
    if (obj.morphTargetDictionary) meshes.push(obj);
    const mats = Array.isArray(obj.material) ? obj.material : [obj.material];
    const flat = mats.map((m) => new THREE.MeshLambertMaterial({
      color: m.color ? m.color.clone() : new THREE.Color(1, 1, 1),
      vertexColors: !!m.vertexColors, side: m.side, flatShading: true }));
    obj.material = Array.isArray(obj.material) ? flat : flat[0];
  });
  const view = rowMajor(req.view);
  const camera = new THREE.Camera();
  camera.projectionMatrix.copy(rowMajor(req.projection));
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  camera.matrixAutoUpdate = false;
  camera.matrix.copy(view).invert();
  camera.matrixWorld.copy(camera.matrix);
  camera.matrixWorldInverse.copy(view);
  scene.add(new THREE.AmbientLight(0xffffff, 0.30 * Math.PI));
  const key = new THREE.DirectionalLight(0xffffff, 0.75 * Math.PI);
  key.position.copy(new THREE.Vector3(-0.35, 0.45, 0.82).normalize())
    .applyMatrix3(new THREE.Matrix3().setFromMatrix4(view).transpose());
  scene.add(key, key.target);
  const [w, h] = req.viewport;
  const renderer = new THREE.WebGLRenderer({ antialias: false, alpha: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(w, h, false);
  renderer.setClearColor(0x000000, 0);
  document.body.appendChild(renderer.domElement);
  const gl = renderer.getContext();
  const out = [];
  const unknown = new Set();
  for (const p of req.poses) {
    for (const m of meshes) m.morphTargetInfluences.fill(0);
    for (const [name, value] of Object.entries(p.weights)) {
      let hit = false;
      for (const m of meshes) {
        const i = m.morphTargetDictionary[name];
        if (i !== undefined) { m.morphTargetInfluences[i] = value; hit = true; }
      }
      if (!hit) unknown.add(name);
    }
    turn.matrix.copy(rowMajor(p.turn));
    scene.updateMatrixWorld(true);
    renderer.render(scene, camera);
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let s = '';
    for (let i = 0; i < px.length; i += 0x8000) s += String.fromCharCode.apply(null, px.subarray(i, i + 0x8000));
    out.push(btoa(s));
  }
  renderer.dispose();
  return { frames: out, unknown: [...unknown] };
}"""


@dataclass
class Pose:
    """Morph weights by target name and a head turn (yaw, pitch, roll radians, R = Ry Rx Rz as blendshapes.drive)."""

    weights: dict[str, float]
    head: tuple[float, float, float] = (0.0, 0.0, 0.0)


def turn_matrix(pivot: np.ndarray, head: Sequence[float]) -> list[list[float]]:
    """The 4x4 row-major world transform turning the head about pivot: T(pivot) R T(-pivot)."""
    r = rotations(np.array([head], np.float64))[0]
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = np.asarray(pivot, np.float64) - r @ np.asarray(pivot, np.float64)
    return m.tolist()


def threejs_posed(browser, gltf: Path, camera, pivot: np.ndarray,
                  poses: Sequence[Pose]) -> tuple[np.ndarray, list[str]]:
    """RGBA uint8 (N, H, W, 4) three.js renders (flat Lambert in our light rig) of gltf at each pose with camera
    (converter.camera.Camera), and the weight names no mesh of the glTF has."""
    width, height = camera.width, camera.height
    gltf = Path(gltf).resolve()
    req = {"url": f"{ORIGIN}/data/{gltf.name}", "view": np.asarray(camera.view).tolist(),
           "projection": np.asarray(camera.projection).tolist(), "viewport": [width, height],
           "poses": [{"weights": {k: float(v) for k, v in p.weights.items()},
                      "turn": turn_matrix(pivot, p.head)} for p in poses]}
    result = _reference_run(browser, gltf, width, height, POSE_JS, req)
    raw = [np.frombuffer(base64.b64decode(f), np.uint8).reshape(height, width, 4)[::-1] for f in result["frames"]]
    return np.stack(raw), list(result["unknown"])


def puppet_posed(browser, page_bytes: bytes, poses: Sequence[Pose]) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of the puppet player's canvas at each pose, set through its API (puppet.set)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "puppet.html"
        path.write_bytes(page_bytes)
        page = browser.new_page(viewport={"width": 1024, "height": 1024})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        try:
            page.goto(path.as_uri() + "?paused")
            page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=120000)
            if page.evaluate("() => document.documentElement.dataset.puppet") != "ready":
                raise RuntimeError(f"the puppet did not start: {errors}")
            page.evaluate("() => puppet.pause()")
            out = []
            for p in poses:
                values = {**{k: float(v) for k, v in p.weights.items()}, "headYaw": float(p.head[0]),
                          "headPitch": float(p.head[1]), "headRoll": float(p.head[2])}
                url = page.evaluate("(v) => { const z = {}; for (const k of Object.keys(puppet.weights())) z[k] = 0;"
                                    " puppet.set(Object.assign(z, v)).render();"
                                    " return document.getElementById('puppet-canvas').toDataURL('image/png'); }",
                                    values)
                out.append(np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA")))
        finally:
            page.close()
    return np.stack(out)


def prerender_posed(face, camera, poses: Sequence[Pose]) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of our 3D prerender (converter/render.py) of face at each pose, lit by our rig
    (vertex normals of each posed frame, GL-interpolated: the render draws Gouraud)."""
    names = list(face.names)  # every target, so a pose with no weights still drives the face
    track = WeightTrack(names, np.arange(len(poses)) / 30.0,
                        np.array([[p.weights.get(n, 0.0) for n in names] for p in poses], np.float32), 30.0,
                        head=np.array([p.head for p in poses], np.float32))
    anim = blendshapes.drive(face, track)
    base = srgb_to_linear(face.still(1.0).face_base_colors()[None])
    rgb = lambert_linear(unit_vertex_normals(anim.frames, anim.faces), np.broadcast_to(base, anim.frames.shape),
                         camera.view, DEFAULT_LIGHTING)  # sRGB-encoded, as the puppet's colours
    shots = render.render_frames(anim.frames, anim.faces, rgb, camera, list(range(len(poses))))
    return np.stack([shots[k] for k in range(len(poses))])


def luminance(rgba: np.ndarray, background: float = 0.0) -> np.ndarray:
    """Rec. 709 luma (0..255) of an RGBA image composited over a grey level."""
    a = rgba[..., 3].astype(np.float64) / 255
    y = rgba[..., :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    return y * a + background * (1 - a)


def ssim_luma(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM (Wang et al. 2004: Gaussian window sigma 1.5, K1 0.01, K2 0.03) of the two images' luminance, averaged
    over the union of their silhouettes (the empty background would otherwise lift the score)."""
    ya, yb = luminance(a), luminance(b)
    _, full = structural_similarity(ya, yb, data_range=255.0, gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False, full=True)
    union = (a[..., 3] > ALPHA) | (b[..., 3] > ALPHA)
    return float(full[union].mean()) if union.any() else 1.0


def silhouette_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of the two RGBA images' silhouettes."""
    return iou(a[..., 3] > ALPHA, b[..., 3] > ALPHA)


def angle_sweep(browser, face, puppet_page: bytes, camera,
                angles: Sequence[float]) -> list[tuple[str, float, float, float, float]]:
    """(axis, degrees, IoU, SSIM, in view) of the puppet against our 3D prerender, head yaw then pitch at each
    angle, no morph weights; in view: the prerender's silhouette area over its area at rest (a full-body avatar
    turns about its bounding box centre, so a large pitch swings its head out of the frame)."""
    poses = [Pose({}, (math.radians(d), 0.0, 0.0)) for d in angles] + \
            [Pose({}, (0.0, math.radians(d), 0.0)) for d in angles]
    ours = puppet_posed(browser, puppet_page, poses)
    ref = prerender_posed(face, camera, [Pose({}), *poses])
    rest = max(int((ref[0][..., 3] > ALPHA).sum()), 1)
    axes = ["yaw"] * len(angles) + ["pitch"] * len(angles)
    return [(ax, float(d), silhouette_iou(o, r), ssim_luma(o, r), float((r[..., 3] > ALPHA).sum() / rest))
            for ax, d, o, r in zip(axes, [*angles, *angles], ours, ref[1:])]
