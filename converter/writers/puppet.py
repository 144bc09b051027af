"""The puppet output: one self-contained HTML file holding a 2D face (converter.puppet) and a player for it.

The page carries three blocks and the inlined script (converter/writers/puppet.js, package data):

- `puppet-meta` (JSON): viewport, the camera's world -> clip matrix and its inverse, the head's pivot and eyes'
  centres, the parameters (name, keyform weights, steps, VRM rules), the capture-name aliases, each array's place
  in the data block;
- `puppet-data`: the arrays, little-endian, each 4-byte aligned, small signed integers zigzag-coded (0, -1, 1,
  -2, ...) as uint16 byte planes (low bytes, then high bytes: deflate finds the runs), deflated (zlib) and base64.
  The neutral positions are integers on the model's grid, coded as differences from the previous vertex (x column,
  then y); a triangle as the gap from the previous triangle's first corner and its other corners' offsets from it;
  a table's keyforms as x row then y row; the unlit base colours as a palette and indices, and the rest normals
  (per triangle when flat, per vertex when Gouraud) as octahedral int8 pairs, each column coded as byte differences
  from the previous element (modulo 256: neighbours face alike, deflate finds the zeros): the player lights them as
  converter/lighting.py does (`light` in the metadata), turned by the head, so the face relights as it turns;
- `puppet-take`: the embedded capture (model.Take) the same way, its own JSON in `data-meta`; `replace_take`
  swaps it for another without touching the rest (`facesvg puppet-take`).

The script draws with WebGL (depth-tested triangles, the morphs and eye turns summed in JS each frame, and only when
they changed; WebGL2 keeps them in a float texture, the vertices the morphs move in its first rows, the only ones
uploaded, turns the head in the vertex shader with one matrix and draws indexed, a flat triangle's colour from a last
corner of its own; WebGL1 rebuilds every corner in script) or, without WebGL, rasterises them itself as GL would
(pixel centres, a depth buffer, back faces dropped) into an image it puts on a canvas 2D in one call (a path and a
fill per triangle cost far more: bench_puppet). The WebGL drawing buffer is not preserved once composited: read the
canvas in the task that draws it (`puppet.render()` then `toDataURL`). It refuses a package whose format or version it
does not know (VERSION), with a message saying so. It evaluates no strings and fetches nothing; the only connection it
opens is the WebSocket a user names (`?live=ws://...` or the Live field). `?embed`, or a frame element carrying
`data-puppet-embed` (the web app's /live page), hides its Play and Live rows for a page that drives it itself.
"""

from __future__ import annotations

import base64
import binascii
import html
import json
import re
import zlib
from importlib import resources

import numpy as np

from converter.errors import InputError
from converter.lighting import DEFAULT_LIGHTING, light_direction_world
from converter.options import ConversionOptions, Progress, Report, no_progress
from converter.puppet.model import EYE_UNIT, HEAD_UNIT, NEUTRAL_XY_STEP, NEUTRAL_Z_STEP, Parameter, Puppet, Take

FORMAT = "facesvg-puppet"
VERSION = 3  # 2: integer neutral positions, zigzag planes, colour palette; 3: unlit base colours and rest normals
MARKER = '<meta name="generator" content="facesvg puppet">'
META_ID, DATA_ID, TAKE_ID = "puppet-meta", "puppet-data", "puppet-take"
_TAKE = re.compile(rb'<script type="application/octet-stream" id="puppet-take"[^>]*>[^<]*</script>')
_BLOCK = re.compile(rb'<script type="application/(?:json|octet-stream)" id="(puppet-[a-z]+)"([^>]*)>([^<]*)</script>')


def puppet_script() -> str:
    """The player's JavaScript source (package data next to this module)."""
    return resources.files("converter.writers").joinpath("puppet.js").read_text(encoding="utf-8")


def is_puppet(data: bytes) -> bool:
    """True when the bytes are a puppet HTML file written by this module."""
    return MARKER.encode() in data[:4096]


class _Packer:
    """Arrays laid out one after another, 4-byte aligned, and where each is: name -> [offset, dtype, length]."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0
        self.index: dict[str, list] = {}

    def add(self, name: str, a: np.ndarray, planes: bool = False) -> None:
        """Append an array (int16 as byte planes when planes)."""
        a = np.ascontiguousarray(a)
        kind = {np.dtype(np.float32): "f4", np.dtype(np.int32): "i4", np.dtype(np.int16): "i2",
                np.dtype(np.uint8): "u1", np.dtype(np.int8): "i1", np.dtype(np.uint16): "u2"}[a.dtype]
        raw = a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes()
        if planes and a.dtype.itemsize == 2:  # "i2p" / "u2p"
            b = np.frombuffer(raw, np.uint8).reshape(-1, 2)
            raw = b[:, 0].tobytes() + b[:, 1].tobytes()
            kind += "p"
        self.index[name] = [self.size, kind, int(a.size)]
        pad = -len(raw) % 4
        self.parts.append(raw + b"\0" * pad)
        self.size += len(raw) + pad

    def ints(self, name: str, a: np.ndarray) -> None:
        """Append signed integers: zigzag uint16 byte planes where they fit int16, else int32."""
        a = np.asarray(a, np.int64).ravel()
        if a.size and (a.min() < -32768 or a.max() > 32767):
            self.add(name, a.astype(np.int32))
            return
        self.add(name, ((a << 1) ^ (a >> 63)).astype(np.uint16), planes=True)
        self.index[name][1] = "zp"

    def bytes(self) -> bytes:
        """The block."""
        return b"".join(self.parts)


def predicted(q_last: np.ndarray, w: float) -> np.ndarray:
    """A keyform at weight w predicted from the last keyform (weight 1) as linear: floor(w q + 1/2), as the
    script rounds it."""
    return np.floor(w * q_last.astype(np.float64) + 0.5).astype(np.int64)


def _residuals(q: np.ndarray, weights: np.ndarray) -> np.ndarray | None:
    """Keyforms (S, ...) with the inner ones as their difference from the linear prediction, or None where a
    difference would not fit int16. A target near linear in its weight then stores near-zero inner keyforms."""
    out = q.astype(np.int64).copy()
    for s in range(1, len(q) - 1):
        out[s] -= predicted(q[-1], float(weights[s]))
    if np.abs(out).max(initial=0) > 32767:
        return None
    return out.astype(np.int16)


def _parameter(p: Parameter, key: str, packer: _Packer) -> dict:
    """A parameter's JSON, its arrays added to the block under key: vertex ids as gaps from the previous one, inner
    keyforms as residuals from the linear prediction where they fit."""
    t = p.table
    gaps = np.diff(t.vertices.astype(np.int64), prepend=0).astype(np.int32)
    packer.ints(key + ".v", gaps)
    rxy, rz = _residuals(t.xy, p.axes[0]), _residuals(t.z, p.axes[0])
    residual = rxy is not None and rz is not None and len(p.axes[0]) > 2
    packer.ints(key + ".xy", np.moveaxis(rxy if residual else t.xy, 2, 1))  # (S, 2, M): x row, then y row
    packer.ints(key + ".z", rz if residual else t.z)
    doc = {"name": p.name, "axes": [[float(x) for x in a] for a in p.axes],
           "xyStep": t.xy_step, "zStep": t.z_step, "key": key, "moved": int(len(t.vertices))}
    if residual:
        doc["residual"] = True
    if p.clamp:
        doc["clamp"] = True
    if p.binary:
        doc["binary"] = True
    return doc


def _colors(colors: np.ndarray, packer: _Packer) -> None:
    """Add the colours as a palette (in order of first use) and uint16 indices into it, or as they are where more
    than 65,536 differ."""
    rgb = np.ascontiguousarray(colors.astype(np.uint8).reshape(len(colors), -1))
    palette, first, index = np.unique(rgb, axis=0, return_index=True, return_inverse=True)
    if len(palette) > 65536:
        packer.add("colors", rgb)
        return
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    packer.add("palette", palette[order])
    packer.add("colorIndex", rank[index.ravel()].astype(np.uint16), planes=True)


def encode(puppet: Puppet) -> tuple[dict, bytes]:
    """The metadata and the (raw) data block of a puppet."""
    packer = _Packer()
    m = puppet.camera.projection @ puppet.camera.view  # world -> clip, row-major: the player's unproject and project
    qxy = np.rint(puppet.xy.astype(np.float64) / NEUTRAL_XY_STEP).astype(np.int64)
    packer.ints("xy", np.diff(qxy, axis=0, prepend=0).T)
    packer.ints("z", np.diff(np.rint(puppet.z.astype(np.float64) / NEUTRAL_Z_STEP).astype(np.int64), prepend=0))
    t = puppet.triangles.astype(np.int64).reshape(-1, 3)
    packer.ints("tris", np.c_[np.diff(t[:, 0], prepend=0), t[:, 1:] - t[:, :1]])
    _colors(puppet.base_colors, packer)
    codes = puppet.normals.astype(np.int64)
    packer.add("normals", np.ascontiguousarray((np.diff(codes, axis=0, prepend=0) % 256).astype(np.uint8).T))
    meta = {
        "format": FORMAT, "version": VERSION, "name": puppet.name, "width": puppet.width, "height": puppet.height,
        "xyUnit": NEUTRAL_XY_STEP, "zUnit": NEUTRAL_Z_STEP, "vertices": int(len(puppet.xy)),
        "triangles": int(len(puppet.triangles)), "gouraud": puppet.gouraud,
        "pivot": [float(x) for x in puppet.pivot],
        "light": {"direction": [float(x) for x in light_direction_world(puppet.camera.view, DEFAULT_LIGHTING)],
                  "diffuse": DEFAULT_LIGHTING.diffuse, "ambient": DEFAULT_LIGHTING.ambient},
        "matrix": [float(x) for x in m.ravel()], "inverse": [float(x) for x in np.linalg.inv(m).ravel()],
        "morphs": [_parameter(p, f"m{k}", packer) for k, p in enumerate(puppet.morphs)],
        "eyes": [{"key": f"e{k}", "centre": [float(x) for x in c]} for k, c in enumerate(puppet.eye_centres)],
        "aliases": {n: [[k, f] for k, f in pairs] for n, pairs in sorted(puppet.aliases.items())},
        "keys": [list(k) for k in puppet.keys],
        "camera": puppet.camera.to_json(),
        "info": {k: v for k, v in puppet.info.items() if isinstance(v, (int, float, str))},
    }
    for k, ids in enumerate(puppet.eyes):
        packer.ints(f"e{k}.v", ids)
    meta["arrays"] = packer.index
    return meta, packer.bytes()


def encode_take(take: Take | None) -> tuple[dict | None, bytes]:
    """The take's metadata and raw block (None and b'' without a take)."""
    if take is None:
        return None, b""
    packer = _Packer()
    packer.add("weights", take.weights.astype(np.uint8))
    if take.head is not None:
        packer.add("head", take.head.astype(np.int16))
    if take.eyes is not None:
        packer.add("eyes", take.eyes.astype(np.int8))
    if take.times is not None:
        packer.add("times", take.times.astype(np.uint16))
    meta = {"names": list(take.names), "frames": take.n_frames, "fps": take.fps, "source": take.source,
            "headUnit": HEAD_UNIT, "eyeUnit": EYE_UNIT, "bytesPerFrame": take.bytes_per_frame,
            "arrays": packer.index}
    return meta, packer.bytes()


def _json_text(doc) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(doc, sort_keys=True, separators=(",", ":")).replace("<", "\\u003c")


def take_element(take: Take | None) -> bytes:
    """The `puppet-take` script element of a take (empty without one)."""
    meta, raw = encode_take(take)
    packed = base64.b64encode(zlib.compress(raw, 9)).decode("ascii") if raw else ""
    attr = html.escape(_json_text(meta), quote=True)
    return (f'<script type="application/octet-stream" id="{TAKE_ID}" data-bytes="{len(raw)}" '
            f'data-meta="{attr}">{packed}</script>').encode()


def write(puppet: Puppet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The puppet HTML: metadata, the deflated data block, the take and the inlined player script."""
    if options.frame is not None:
        raise InputError("--frame makes a still, which the puppet does not; drop --frame or use --to svg.")
    meta, raw = encode(puppet)
    progress("deflate", 0.3)
    packed = zlib.compress(raw, 9)
    report.sizes["puppet_raw"] = len(raw)
    report.sizes["puppet_deflated"] = len(packed)
    take = take_element(puppet.take)
    if puppet.take is not None:
        report.sizes["take_bytes_per_frame"] = puppet.take.bytes_per_frame
    page = HTML.format(title=html.escape(puppet.name), marker=MARKER, width=puppet.width, height=puppet.height,
                       meta=_json_text(meta), meta_id=META_ID, data_id=DATA_ID, bytes=len(raw),
                       data=base64.b64encode(packed).decode("ascii"), style=STYLE, script=puppet_script())
    progress("write", 1.0)
    return page.encode("utf-8").replace(b"<!--take-->", take)


def replace_take(page: bytes, take: Take | None) -> bytes:
    """A puppet HTML file with its embedded take replaced (InputError when the bytes are not a puppet)."""
    if not is_puppet(page) or len(_TAKE.findall(page)) != 1:
        raise InputError("that file is not a puppet written by facesvg (--to puppet); give the puppet's .html.")
    element = take_element(take)
    return _TAKE.sub(lambda m: element, page, count=1)


def read_blocks(page: bytes) -> tuple[dict, bytes, dict | None, bytes]:
    """(meta, data block, take meta, take block) of a puppet HTML file, inflated: what the player reads."""
    if not is_puppet(page):
        raise InputError("that file is not a puppet written by facesvg (--to puppet); give the puppet's .html.")
    found = {m.group(1).decode(): (m.group(2), m.group(3)) for m in _BLOCK.finditer(page)}
    if not {META_ID, DATA_ID, TAKE_ID} <= set(found):
        raise InputError("the puppet file lacks its data blocks; regenerate it.")
    try:
        meta = json.loads(found[META_ID][1])
        data = zlib.decompress(base64.b64decode(found[DATA_ID][1], validate=True))
        attr = re.search(rb'data-meta="([^"]*)"', found[TAKE_ID][0])
        take_meta = json.loads(html.unescape(attr.group(1).decode())) if attr else None
        take_raw = found[TAKE_ID][1].strip()
        take = zlib.decompress(base64.b64decode(take_raw, validate=True)) if take_raw else b""
    except (ValueError, binascii.Error, zlib.error):
        raise InputError("the puppet file's data blocks are corrupt; regenerate it.") from None
    return meta, data, take_meta, take


def array(block: bytes, entry: list) -> np.ndarray:
    """One array of a block from its index entry [offset, dtype, length] (byte planes put back together)."""
    offset, kind, n = entry
    planes = kind.endswith("p")
    dtype = np.dtype("<u2" if kind == "zp" else "<" + kind.rstrip("p"))
    raw = block[offset:offset + n * dtype.itemsize]
    if planes:
        b = np.frombuffer(raw, np.uint8)
        raw = np.stack([b[:n], b[n:]], axis=1).tobytes()
    out = np.frombuffer(raw, dtype).copy()
    if kind == "zp":
        u = out.astype(np.int64)
        return (u >> 1) ^ -(u & 1)
    return out


def decode_mesh(block: bytes, meta: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The neutral (xy (V, 2) px, z (V,)) and triangles (F, 3) from the block, as the script reads them."""
    a, v = meta["arrays"], meta["vertices"]
    q = np.cumsum(array(block, a["xy"]).reshape(2, v), axis=1).T
    z = np.cumsum(array(block, a["z"])) * meta["zUnit"]
    t = array(block, a["tris"]).reshape(-1, 3)
    first = np.cumsum(t[:, 0])
    tris = np.c_[first, first + t[:, 1], first + t[:, 2]]
    return (q * meta["xyUnit"]).astype(np.float32), z.astype(np.float32), tris


def decode_normals(block: bytes, meta: dict) -> np.ndarray:
    """The (N, 2) int8 octahedral rest normals from the block (byte differences summed modulo 256)."""
    d = array(block, meta["arrays"]["normals"]).reshape(2, -1).T.astype(np.int64)
    return np.cumsum(d, axis=0).astype(np.uint8).view(np.int8)


def decode_colors(block: bytes, meta: dict) -> np.ndarray:
    """The (N, 3) uint8 unlit base colours from the block (palette and indices, or as they are)."""
    a = meta["arrays"]
    if "colors" in a:
        return array(block, a["colors"]).reshape(-1, 3)
    return array(block, a["palette"]).reshape(-1, 3)[array(block, a["colorIndex"]).astype(np.int64)]


def decode_parameter(block: bytes, meta: dict, doc: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A parameter's (vertex ids (M,), xy (S, M, 2), z (S, M)) int arrays from the block, as the script reads them."""
    a = meta["arrays"]
    ids = np.cumsum(array(block, a[doc["key"] + ".v"]).astype(np.int64))
    s, m = len(doc["axes"][0]), len(ids)
    xy = np.moveaxis(array(block, a[doc["key"] + ".xy"]).astype(np.int64).reshape(s, 2, m), 1, 2).copy()
    z = array(block, a[doc["key"] + ".z"]).astype(np.int64).reshape(s, m)
    if doc.get("residual"):
        for k in range(1, s - 1):
            xy[k] += predicted(xy[-1], doc["axes"][0][k])
            z[k] += predicted(z[-1], doc["axes"][0][k])
    return ids, xy, z


STYLE = """
html{color-scheme:light dark}body{margin:0;font:14px/1.4 system-ui,sans-serif}
#puppet{display:flex;flex-wrap:wrap;gap:12px;padding:8px;align-items:flex-start}
#puppet-stage{display:flex;flex-direction:column;gap:6px}
#puppet-canvas{display:block;max-width:100%;height:auto;background:transparent}
.puppet-row{display:flex;align-items:center;gap:8px;flex-wrap:wrap}.puppet-row[hidden]{display:none}
.puppet-row input[type=range]{flex:1;min-width:80px}
#puppet-live-url{flex:1;min-width:160px}
#puppet-sliders{max-height:80vh;overflow:auto;min-width:260px}
#puppet-sliders label{display:grid;grid-template-columns:10em 1fr 3.5em;gap:6px;align-items:center;font-size:12px}
#puppet-status{font-size:12px;opacity:.8}
"""

HTML = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">{marker}
<meta name="viewport" content="width=device-width,initial-scale=1">
<title>{title}</title>
<style>{style}</style>
</head><body>
<div id="puppet">
<div id="puppet-stage">
<canvas id="puppet-canvas" width="{width}" height="{height}" aria-label="{title}: face puppet"></canvas>
<div class="puppet-row" id="puppet-controls">
<button type="button" id="puppet-play" aria-pressed="false">Play</button>
<input type="range" id="puppet-scrub" min="0" max="1" step="any" value="0" aria-label="Time">
<output id="puppet-time">0.00 s</output>
</div>
<div class="puppet-row" id="puppet-live-row">
<input type="url" id="puppet-live-url" placeholder="ws://host:port (live weights)" aria-label="Live WebSocket URL">
<button type="button" id="puppet-live">Connect</button>
</div>
<p id="puppet-status" role="status">Loading...</p>
</div>
<details id="puppet-panel" open><summary>Parameters</summary><div id="puppet-sliders"></div>
<button type="button" id="puppet-reset">Reset</button></details>
</div>
<script type="application/json" id="{meta_id}">{meta}</script>
<script type="application/octet-stream" id="{data_id}" data-bytes="{bytes}">{data}</script>
<!--take-->
<script>{script}</script>
</body></html>
"""
