"""Independent Lottie references: two real players and the Lottie spec's JSON schema (issue 51).

lottie-web (its svg and canvas renderers) and ThorVG (through dotlottie-web's `DotLottie`, a WASM build of ThorVG
drawing into a canvas) play a Lottie document in headless Chromium; `schema_errors` validates a document against
the schema the Lottie Animation Community publishes (lottie-specs). All three come from npm (`npm ci` in this
folder); the page (lottie_page.html + lottie_page.js) and the packages, ThorVG's WASM included, are served from
disk by request interception under ORIGIN, so nothing is fetched from a CDN. None of this reads our writer's code.

Frames are the composition's Lottie frame numbers (ip..op, fractional allowed): lottie-web seeks with
goToAndStop(frame - ip, true) (sub-frames on), ThorVG with setFrame(frame - ip) (frame interpolation on); both
count from ip alike (test_dotlottie_and_ip_offset). Past the last frame they differ: at frame == op lottie-web
draws nothing and ThorVG still the last frame, so sample frames ip..op-1 only.

What test_lottie_reference.py verified (lottie-web 5.13.0, dotlottie-web 0.80.0, Chromium headless):

- Transform order. A `tr` (group) or layer `ks` maps a point x (column vectors, y down, degrees, s in percent) as
  T(p) . R(r) . R(-sa) . Kx(-sk) . R(sa) . S(s/100) . T(-a) . x: anchor first, then scale, then skew along the
  axis sa, then rotation, then position (tr_matrix); a layer's `ks` applies outside its groups' `tr`
  (layer @ group). R(d) = [[cos d, -sin d], [sin d, cos d]] is SVG's rotate(d): positive r turns clockwise on
  screen, as in SVG. Kx(d) = [[1, tan d], [0, 1]] is SVG's skewX(d), so Lottie's skew has the OPPOSITE sign: sk = +20 is
  skewX(-20); and the axis turns the other way too (R(-sa) before the skew, R(sa) after it). All three players
  agree with this to IoU >= 0.986 on an animated group under a rotated layer; flipping sk's or sa's sign drops it
  to 0.32-0.36 at the last key.
- SVG to Lottie: `transform="translate(tx ty) rotate(t) skewX(f) scale(sx sy)"` is the `tr`
  {a: [0, 0], p: [tx, ty], r: t, sk: -f, sa: 0, s: [100 sx, 100 sy]} (checked against Chromium drawing the SVG).
- Shape keyframes interpolate the vertices linearly with easing o = (0, 0), i = (1, 1); a colour key with h: 1
  holds until the next key (within 1 level: 0.5 green is 127 in lottie-web and 128 in ThorVG). In a group, the
  style listed first draws on top (a stroke before the fill covers it). Several `sh` before one `fl` are all
  filled by it (merged paths).
- A closed triangle collapsed to a point (three equal vertices) with a 0.6 px stroke: with round caps (lc 2) or
  square caps (lc 3) lottie-web's svg renderer draws a dot (Chromium's SVG stroker caps zero-length subpaths:
  max alpha ~145 over 4 pixels, ~0.7 px of coverage), its canvas renderer and ThorVG draw nothing; with butt caps
  (lc 1) none draws anything. A writer that hides a path by collapsing it must use butt caps (or hide it
  otherwise) for the players to agree. The fill of the collapsed triangle draws nothing anywhere.
- The spec's schema (lottie-specs 0.3.2, draft 2020-12, every $ref local) passes unknown layer and shape `ty`
  values on purpose (players skip them): schema_errors(doc, strict=True) also reports those.
"""

from __future__ import annotations

import base64
import functools
import io
import json
import mimetypes
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from jsonschema.exceptions import ValidationError
from PIL import Image
from playwright.sync_api import Browser
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from referencing import Registry, Resource
from referencing.jsonschema import DRAFT202012

from bench.playback import measure, serve
from tests.conftest import chromium_path, launched_chromium

HERE = Path(__file__).resolve().parent
NODE = HERE / "node_modules"
PACKAGES = {  # npm package -> its package.json once installed
    "lottie-web": NODE / "lottie-web" / "package.json",
    "@lottiefiles/dotlottie-web": NODE / "@lottiefiles" / "dotlottie-web" / "package.json",
    "@lottie-animation-community/lottie-specs": NODE / "@lottie-animation-community" / "lottie-specs" / "package.json",
}
SCHEMA = NODE / "@lottie-animation-community" / "lottie-specs" / "src" / "data" / "lottie.schema.json"
PAGE_FILES = ("lottie_page.html", "lottie_page.js")
PLAYERS = ("lottie-svg", "lottie-canvas", "thorvg")
ORIGIN = "http://lottie-reference.invalid"  # never resolved: every request under it is answered from disk
ZIP_MAGIC = b"PK\x03\x04"
LOAD_MS = 60000


def missing() -> str | None:
    """Why the Lottie reference cannot run here (no node/npm, or `npm ci` not run), or None."""
    absent = [name for name, path in PACKAGES.items() if not path.exists()]
    if absent or not SCHEMA.exists():
        if shutil.which("npm") is None:
            return f"node/npm not installed (apt-get install nodejs npm), so {', '.join(absent)} missing"
        return f"{', '.join(absent) or 'the Lottie schema'} not installed: run `npm ci` in {HERE}"
    return None


def require() -> None:
    """Skip the calling test where the Lottie reference cannot run (missing()); fail instead when CI is set."""
    why = missing()
    if why:
        if os.environ.get("CI"):
            pytest.fail(f"{why}, but CI is set: `make setup` must run npm ci")
        pytest.skip(why)


def versions() -> dict[str, str]:
    """The installed version of each reference package."""
    return {name: json.loads(path.read_text())["version"] for name, path in PACKAGES.items()}


def animation_of(doc: dict | bytes) -> tuple[dict, bytes | None]:
    """(the Lottie animation as a dict, the dotLottie zip or None) of a document: a dict, Lottie JSON bytes, or a
    dotLottie zip (its manifest's first animation, animations/<id>.json)."""
    if isinstance(doc, dict):
        return doc, None
    if not doc.startswith(ZIP_MAGIC):
        return json.loads(doc), None
    try:
        with zipfile.ZipFile(io.BytesIO(doc)) as zf:
            names = set(zf.namelist())
            ids = []
            if "manifest.json" in names:
                ids = [a["id"] for a in json.loads(zf.read("manifest.json")).get("animations", []) if "id" in a]
            candidates = [f"animations/{i}.json" for i in ids] + sorted(
                n for n in names if n.startswith("animations/") and n.endswith(".json"))
            for name in candidates:
                if name in names:
                    return json.loads(zf.read(name)), doc
    except zipfile.BadZipFile as exc:
        raise ValueError(f"not a readable dotLottie zip: {exc}") from None
    raise ValueError("the dotLottie file holds no animations/*.json")


@contextmanager
def _chromium(browser: Browser | None) -> Iterator[Browser]:
    """The given browser, or a headless Chromium for the length of the block."""
    if browser is not None:
        yield browser
        return
    exe = chromium_path()
    if not exe:
        raise RuntimeError("Chromium is not installed (apt-get install chromium)")
    with launched_chromium(exe) as b:
        yield b


def _fulfil(not_found: list[str]):
    def handle(route) -> None:
        url = route.request.url
        if not url.startswith(f"{ORIGIN}/"):  # a CDN or any other host: never fetched
            not_found.append(url)
            route.abort()
            return
        rel = url[len(ORIGIN):].split("?", 1)[0].lstrip("/")
        # normpath, not resolve: node_modules may be a symlink; ".." still cannot climb out of HERE
        target = Path(os.path.normpath(HERE / rel))
        if HERE not in target.parents or not target.is_file():
            not_found.append(rel)
            route.fulfill(status=404, body="not found")
            return
        kind = {".js": "text/javascript", ".mjs": "text/javascript", ".wasm": "application/wasm"}.get(
            target.suffix, mimetypes.guess_type(target.name)[0] or "application/octet-stream")
        route.fulfill(status=200, body=target.read_bytes(), content_type=kind)

    return handle


def lottie_frames(doc: dict | bytes, frames: Sequence[float], player: str, width: int | None = None,
                  height: int | None = None, *, browser: Browser | None = None) -> np.ndarray:
    """RGBA uint8 (N, H, W, 4) of the animation drawn by player at each Lottie frame, on a transparent background.

    player: "lottie-svg" (a screenshot of lottie-web's svg), "lottie-canvas" (lottie-web's canvas) or "thorvg"
    (dotlottie-web's canvas); size: the animation's own (w, h) unless given (the players fit it, centred).
    browser: a Playwright Chromium to use (the tests' session one), else one is launched for the call."""
    if player not in PLAYERS:
        raise ValueError(f"unknown player {player!r}: one of {', '.join(PLAYERS)}")
    anim, zipped = animation_of(doc)
    w, h = int(width or anim["w"]), int(height or anim["h"])
    req = {"player": player, "width": w, "height": h, "ip": float(anim.get("ip", 0)), "json": json.dumps(anim),
           "zip": base64.b64encode(zipped).decode("ascii") if zipped and player == "thorvg" else None}
    with _chromium(browser) as b:
        page = b.new_page(viewport={"width": w, "height": h})
        errors: list[str] = []
        not_found: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        try:
            page.route("**/*", _fulfil(not_found))
            page.goto(f"{ORIGIN}/lottie_page.html")
            try:
                page.wait_for_function("window.lottieReference !== undefined", timeout=LOAD_MS)
            except PlaywrightTimeout:
                raise RuntimeError(f"the Lottie page did not start (errors {errors}, not found {not_found})") from None
            page.evaluate("(req) => window.lottieReference.open(req)", req)
            if player == "lottie-svg":
                shots = []
                for f in frames:
                    page.evaluate("(f) => window.lottieReference.seek(f)", float(f))
                    png = page.screenshot(clip={"x": 0, "y": 0, "width": w, "height": h}, omit_background=True)
                    shots.append(np.asarray(Image.open(io.BytesIO(png)).convert("RGBA")))
                out = np.stack(shots)
            else:
                raw = page.evaluate("(f) => window.lottieReference.frames(f)", [float(f) for f in frames])
                out = np.stack([np.frombuffer(base64.b64decode(r), np.uint8).reshape(h, w, 4) for r in raw])
        finally:
            page.close()
    not_found = [n for n in not_found if not n.endswith("favicon.ico")]
    if errors or not_found:
        raise RuntimeError(f"the Lottie page failed in {player}: {errors} (not found or blocked {not_found})")
    return out


def lottie_fps(doc: dict | bytes, player: str, throttle: int = 1, seconds: float = 5.0, settle: float = 1.0,
               *, browser: Browser | None = None) -> float:
    """requestAnimationFrame callbacks a second while player plays the animation in a loop in headless Chromium
    under throttle x CPU slowdown, counted over `seconds` after `settle` seconds (bench/playback.measure)."""
    if player not in PLAYERS:
        raise ValueError(f"unknown player {player!r}: one of {', '.join(PLAYERS)}")
    anim, zipped = animation_of(doc)
    w, h = int(anim["w"]), int(anim["h"])
    with tempfile.TemporaryDirectory(prefix="facesvg-lottie-") as tmp:
        folder = Path(tmp)
        (folder / "node_modules").symlink_to(NODE, target_is_directory=True)
        for name in PAGE_FILES:
            (folder / name).symlink_to(HERE / name)
        src = "played.lottie" if zipped is not None and player == "thorvg" else "played.json"
        (folder / src).write_bytes(zipped if src.endswith(".lottie") else json.dumps(anim).encode())
        with serve(folder) as base, _chromium(browser) as b:
            got = measure(b, f"{base}/lottie_page.html?play={player}&src={src}&w={w}&h={h}", max(w, h),
                          float(throttle), seconds, warm=settle, state="() => window.lottiePlayed")
    if got is None:
        raise RuntimeError(f"{player} showed no frame of the animation")
    state = got.state or {}
    if state.get("error") or not state.get("frames"):
        raise RuntimeError(f"{player} did not play the animation: {state}")
    return got.fps_raf


def tr_matrix(a: Sequence[float] = (0, 0), p: Sequence[float] = (0, 0), s: Sequence[float] = (100, 100),
              r: float = 0.0, sk: float = 0.0, sa: float = 0.0) -> np.ndarray:
    """The 3x3 matrix of a Lottie transform (degrees, scale in percent) as the three players apply it to points
    (column vectors, y down): T(p) R(r) R(-sa) Kx(-sk) R(sa) S(s/100) T(-a) (module docstring)."""

    def rot(deg: float) -> np.ndarray:
        c, n = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        return np.array([[c, -n, 0], [n, c, 0], [0, 0, 1]])

    def move(v: Sequence[float]) -> np.ndarray:
        return np.array([[1, 0, v[0]], [0, 1, v[1]], [0, 0, 1]], float)

    skew_x = np.array([[1, np.tan(np.radians(-sk)), 0], [0, 1, 0], [0, 0, 1]])
    scale = np.diag([s[0] / 100, s[1] / 100, 1.0])
    return move(p) @ rot(r) @ rot(-sa) @ skew_x @ rot(sa) @ scale @ move([-a[0], -a[1]])


@functools.cache
def _validator() -> Draft202012Validator:
    schema = json.loads(SCHEMA.read_text())
    # Every $ref is local ("#/$defs/..."): the registry holds the schema under its own $id, so nothing is fetched.
    registry = Registry().with_resource(schema["$id"], Resource.from_contents(schema, DRAFT202012))
    return Draft202012Validator(schema, registry=registry)


def _leaf(error: ValidationError) -> ValidationError:
    """The most specific error under a oneOf/anyOf failure: from the branches whose tag fits the object (a layer or
    shape is one of many types told apart by a `ty` const, a property static or animated by an `a` const), else
    the deepest error."""
    while error.context:
        branches: dict = {}
        for e in error.context:
            branches.setdefault(e.relative_schema_path[0], []).append(e)
        typed = [e for errs in branches.values()
                 if not any(x.validator in ("const", "not") and len(x.relative_path) == 1 for x in errs) for e in errs]
        error = max(typed or error.context, key=lambda e: (bool(e.context), len(e.absolute_path)))
    return error


@functools.cache
def known_types() -> dict[str, frozenset]:
    """The layer and shape `ty` values the spec defines ({"layer": ..., "shape": ...}), from its schema."""
    defs = json.loads(SCHEMA.read_text())["$defs"]
    return {"layer": frozenset(defs["layers"]["unknown-layer"]["properties"]["ty"]["not"]["enum"]),
            "shape": frozenset(defs["shapes"]["unknown-shape"]["properties"]["ty"]["not"]["enum"])}


def _unknown_types(doc: dict) -> list[str]:
    """"path: ..." for each layer or shape whose `ty` the spec does not define (the schema itself allows them)."""
    known = known_types()
    out = []

    def shapes(items, path: str) -> None:
        for i, shape in enumerate(items if isinstance(items, list) else []):
            if isinstance(shape, dict):
                if shape.get("ty") not in known["shape"]:
                    out.append(f"{path}/{i}/ty: {shape.get('ty')!r} is not a shape type of the spec")
                shapes(shape.get("it"), f"{path}/{i}/it")

    def layers(items, path: str) -> None:
        for i, layer in enumerate(items if isinstance(items, list) else []):
            if isinstance(layer, dict):
                if layer.get("ty") not in known["layer"]:
                    out.append(f"{path}/{i}/ty: {layer.get('ty')!r} is not a layer type of the spec")
                shapes(layer.get("shapes"), f"{path}/{i}/shapes")

    layers(doc.get("layers"), "layers")
    for k, asset in enumerate(doc.get("assets") or []):
        if isinstance(asset, dict):
            layers(asset.get("layers"), f"assets/{k}/layers")
    return out


def schema_errors(doc: dict, strict: bool = False) -> list[str]:
    """The document's violations of the Lottie spec's JSON schema, one "path: message" each (none when valid);
    strict: also the layer and shape types the spec does not define, which its schema lets through."""
    out = []
    for error in sorted(_validator().iter_errors(doc), key=lambda e: [str(p) for p in e.absolute_path]):
        leaf = _leaf(error)
        path = "/".join(str(p) for p in leaf.absolute_path) or "(root)"
        out.append(f"{path}: {leaf.message}")
    return out + (_unknown_types(doc) if strict and isinstance(doc, dict) else [])
