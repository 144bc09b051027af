"""The player output: one self-contained HTML file that stores every vertex once and draws with WebGL.

The animated SVG repeats each vertex in every triangle's path and leaves the evaluation to the browser's SMIL
engine, which is slow for thousands of animated paths. This file holds the same error-bounded motion in a
compact binary block and plays it with a small script (converter/writers/player.js, inlined):

- per vertex one keyframed 2D track (converter.encode.freeknots, Euclidean bound per point), its keys on the
  integer grid of ErrorBudget.scale, so rounding is part of options.tolerance as in the SVG; keys sit on
  integer frames, so there are no keyTimes to round; with options.rigid, when it saves keys, the tracks are
  local to one head transform (the largest part's affine map per frame, stored every frame as float32 and
  applied once when the player expands the keys), their radius divided by its largest magnification;
- per path (the SVG's drawing order, converter.encode.order.draw_list) its triangle's vertices and its
  visibility as change frames;
- colours as linear keys within COLOR_LEVELS levels (encode.colours.color_keys; the SVG holds discrete steps instead,
  which Chromium's SMIL plays faster, while interpolating costs WebGL nothing): per path for flat shading, per
  vertex for Gouraud (WebGL interpolates vertex colours linearly: exact Gouraud).

Frame k shows at t = k / fps; between frames the player interpolates linearly, as SMIL does; the last key
of every track sits at frame T, the loop end. The SVG's band transforms inside the head are not used.
The script expands the keys once; with WebGL 2 the vertex shader evaluates each frame from textures of them
(WebGL 1 and canvas 2D, the fallbacks, get each frame's corners from the script). WebGL 2 times a multisampled
frame before the first one and starts without multisampling when it takes over 8 ms (half a 60 Hz frame:
software rendering, a weak GPU); multisampling is also dropped when frames come late (player.js, watchPace).

Binary block (little-endian), deflated (zlib, level 9) and base64 in the HTML:
header (HEADER) then the sections in ``encode``'s order, each as byte planes (_section) padded to 4 bytes; key
frames and values are stored per track as the first absolute and then deltas (colours: 8-bit deltas modulo 256).
"""

from __future__ import annotations

import base64
import binascii
import json
import re
import struct
import zlib
from dataclasses import dataclass
from html import escape
from importlib import resources

import numpy as np

from converter.encode import groups, playerplan
from converter.encode.playerplan import COLOR_LEVELS
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, Report, no_progress, span
from converter.sheet import Sheet
from converter.writers.metadata import source_fields

MAGIC = b"FSVP"
VERSION = 1
HEADER = struct.Struct("<4sHHIdIIIIIIIIIII")  # magic, version, flags, frames, fps, width, height, scale,
# vertices, paths, position keys, colour tracks, colour keys, visibility changes, payload bytes, payload CRC-32
FLAG_GOURAUD = 1  # colour tracks per vertex (else per path)
FLAG_WIDE = 2  # position values are int32 (else int16)
FLAG_HEAD = 4  # positions are local to a per-frame head transform (last section: float32 (T + 1, 2, 3))
DEFLATE_CHUNK = 1 << 20  # bytes deflated between progress reports (a fraction of a second at level 9)
MAX_FRAMES = 65534  # key frames are uint16 (frame T, the loop end, included)
MAX_EXPANDED = 1 << 27  # numbers the player may expand (frames x tracks x coordinates) before it refuses
DATA_ID = "facesvg-data"
META_ID = "facesvg"
MARKER = b'<meta name="generator" content="facesvg player">'
_BLOCK = re.compile(rb'<script type="application/(octet-stream|json)" id="(facesvg-data|facesvg)"[^>]*>(.*?)</script>',
                    re.DOTALL)


@dataclass(frozen=True)
class Decoded:
    """The player's data decoded to per-frame arrays (frame T is the loop end)."""

    meta: dict
    frames: int
    fps: float
    width: int
    height: int
    scale: int
    gouraud: bool
    vertex_ids: np.ndarray  # int64 (V,) input vertex of each stored vertex
    triangles: np.ndarray  # int64 (P,) input triangle of each path, back to front
    path_vertices: np.ndarray  # int64 (P, 3) stored vertices of each path
    xy: np.ndarray  # float64 (T + 1, V, 2) px
    shown: np.ndarray  # bool (T, P)
    rgb: np.ndarray  # float64 (T + 1, P or V, 3) 8-bit levels

    def path_xy(self) -> np.ndarray:
        """(T, P, 3, 2) px of every path's vertices at frames 0..T-1."""
        return np.take(self.xy[:-1], self.path_vertices, axis=1)


def player_script() -> str:
    """The player's JavaScript source (package data next to this module)."""
    return resources.files("converter.writers").joinpath("player.js").read_text(encoding="utf-8")


def is_player(data: bytes) -> bool:
    """True when the bytes are a player HTML file written by this module."""
    return MARKER in data[:4096]


def _pack_keys(mask: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keys (mask (T+1, N), values (T+1, N, D)) as per-track counts, frame deltas and value deltas (K, D),
    track-major; the first key of a track holds its absolute frame and value."""
    pk, fk = np.nonzero(mask.T)
    vals = np.rint(values.transpose(1, 0, 2)[pk, fk]).astype(np.int64)
    counts = np.bincount(pk, minlength=mask.shape[1])
    first = np.ones(len(pk), bool)
    first[1:] = pk[1:] != pk[:-1]
    fd = np.diff(fk, prepend=0)
    fd[first] = fk[first]
    vd = np.diff(vals, axis=0, prepend=np.zeros((1, vals.shape[1]), np.int64))
    vd[first] = vals[first]
    return counts, fd, vd


def _changes(active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visibility (T, P) as initial state (P,), change counts (P,) and change frame deltas, path-major."""
    change = np.zeros(active.shape, bool)
    change[1:] = active[1:] != active[:-1]
    pk, fk = np.nonzero(change.T)
    first = np.ones(len(pk), bool)
    first[1:] = pk[1:] != pk[:-1]
    fd = np.diff(fk, prepend=0)
    fd[first] = fk[first]
    return active[0].astype(np.uint8), np.bincount(pk, minlength=active.shape[1]), fd


def _section(a: np.ndarray) -> bytes:
    """An array's bytes as byte planes (every element's first byte, then every second byte, ...: small deltas
    leave whole planes nearly constant, which deflate packs tighter), padded to 4 bytes."""
    planes = np.ascontiguousarray(a).view(np.uint8).reshape(len(a), a.dtype.itemsize).T.tobytes()
    return planes + b"\0" * (-len(planes) % 4)


def encode(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The binary block (header + sections, not yet deflated) of the sheet's animation; progress(stage, fraction of
    the writing done) between its steps."""
    t = sheet.n_frames
    if t > MAX_FRAMES:
        raise InputError(f"the player holds at most {MAX_FRAMES} frames, got {t}; convert a shorter range "
                         "(--start/--end).")
    progress("order", 0.0)
    pp = playerplan.plan(sheet, options, progress)
    budget, tris, active, verts, local = pp.budget, pp.tris, pp.active, pp.verts, pp.local
    q, mats = pp.positions, pp.head
    p, n_v, gouraud = len(tris), len(verts), pp.gouraud
    pc, pf, pv = _pack_keys(q.mask, q.values)
    wide = bool(len(pv)) and (pv.min() < -32768 or pv.max() > 32767)
    cc, cf, cv = _pack_keys(pp.colours.mask, pp.colours.values)
    vis0, vc, vf = _changes(active)
    sections = [
        verts.astype("<u4"), tris.astype("<u4"), local.astype("<u4"),
        vis0.astype("u1"), vc.astype("<u2"), vf.astype("<u2"),
        pc.astype("<u2"), pf.astype("<u2"), pv.astype("<i4" if wide else "<i2"),
        cc.astype("<u2"), cf.astype("<u2"), (cv & 255).astype("u1"),
    ] + ([mats.reshape(-1).astype("<f4")] if mats is not None else [])
    payload = b"".join(_section(np.ascontiguousarray(s).ravel()) for s in sections)
    flags = (FLAG_GOURAUD if gouraud else 0) | (FLAG_WIDE if wide else 0) | (FLAG_HEAD if mats is not None else 0)
    head = HEADER.pack(MAGIC, VERSION, flags, t, float(sheet.fps), sheet.camera.width, sheet.camera.height,
                       budget.scale, n_v, p, len(pf), len(cc), len(cf), len(vf), len(payload),
                       zlib.crc32(payload))
    report.counts["paths"] = p
    report.counts["player_vertices"] = n_v
    report.counts["keys"] = int(len(pf))
    report.counts["player_head_transform"] = int(mats is not None)
    report.counts["color_keys"] = int(len(cf))
    report.counts["visibility_changes"] = int(len(vf))
    report.counts["depth_conflicts"] = pp.conflicts
    report.figures["keys_per_vertex"] = len(pf) / max(n_v, 1)
    report.sizes["player_block"] = len(head) + len(payload)
    return head + payload


def metadata(sheet: Sheet, options: ConversionOptions, scale: int) -> dict:
    """What the verifier needs to re-project the input (the SVG's metadata fields, without the order)."""
    return {
        "format": "facesvg-player",
        "version": VERSION,
        **source_fields(sheet, options),
        "encoding": {"mode": "player", "scale": scale, "tolerance": options.tolerance,
                     "color_levels": COLOR_LEVELS},
    }


def _json_text(doc: dict) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(doc, sort_keys=True, separators=(",", ":")).replace("<", "\\u003c")


def deflate(data: bytes, progress: Progress = no_progress) -> bytes:
    """zlib.compress(data, 9), the same bytes, fed DEFLATE_CHUNK bytes at a time with progress between chunks."""
    z = zlib.compressobj(9)
    view = memoryview(data)
    out = []
    for s in range(0, len(data), DEFLATE_CHUNK):
        progress("deflate", s / max(len(data), 1))
        out.append(z.compress(view[s:s + DEFLATE_CHUNK]))
    out.append(z.flush())
    progress("deflate", 1.0)
    return b"".join(out)


def write(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The player HTML: the deflated block in base64, the metadata and the inlined player script."""
    if options.frame is not None:
        raise InputError("--frame makes a still, which the player does not; drop --frame or use --to svg.")
    block = encode(sheet, options, report, progress)
    packed = deflate(block, span(progress, 0.6, 1.0))  # zlib at level 9: a large share of the writer's CPU
    report.sizes["player_deflated"] = len(packed)
    scale = HEADER.unpack_from(block)[7]
    w, h = sheet.camera.width, sheet.camera.height
    page = HTML.format(
        title=escape(sheet.name), width=w, height=h, bytes=len(block), marker=MARKER.decode(),
        meta=_json_text(metadata(sheet, options, scale)), data=base64.b64encode(packed).decode("ascii"),
        style=STYLE, script=player_script(), data_id=DATA_ID, meta_id=META_ID,
    )
    return page.encode("utf-8")


STYLE = """
[hidden]{display:none!important}html{color-scheme:light dark}body{margin:0;font:14px/1.4 system-ui,sans-serif}
#facesvg-player{display:inline-flex;flex-direction:column;gap:6px;padding:8px;max-width:100%;box-sizing:border-box}
#facesvg-canvas{display:block;max-width:100%;height:auto;cursor:pointer}
#facesvg-message{margin:0;padding:8px;border:1px solid #b00;color:#b00;background:#fff0f0}
.facesvg-controls{display:flex;align-items:center;gap:8px}
.facesvg-controls input[type=range]{flex:1;min-width:80px}
"""

HTML = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">{marker}
<meta name="viewport" content="width=device-width,initial-scale=1">
<title>{title}</title>
<style>{style}</style>
</head><body>
<div id="facesvg-player" data-state="loading">
<canvas id="facesvg-canvas" width="{width}" height="{height}" aria-label="{title}: face animation"></canvas>
<p id="facesvg-message" role="alert" hidden></p>
<div class="facesvg-controls">
<button type="button" id="facesvg-play" aria-pressed="false">Play</button>
<input type="range" id="facesvg-scrub" min="0" max="1" step="any" value="0" aria-label="Time">
<label><input type="checkbox" id="facesvg-loop" checked> Loop</label>
<output id="facesvg-time">0.00 s</output>
</div>
</div>
<script type="application/json" id="{meta_id}">{meta}</script>
<script type="application/octet-stream" id="{data_id}" data-bytes="{bytes}">{data}</script>
<script>{script}</script>
</body></html>
"""


# Decoding (the verifier and the tests): the same checks the player makes, in the same order.


def _blocks(data: bytes) -> tuple[dict, bytes, int]:
    """The metadata, the deflated block and its stated length from the player HTML."""
    found = {m.group(2): (m.group(3), m.group(0)) for m in _BLOCK.finditer(data)}
    if DATA_ID.encode() not in found or META_ID.encode() not in found:
        raise InputError("the player file has no data or metadata block; regenerate it.")
    try:
        meta = json.loads(found[META_ID.encode()][0])
        packed = base64.b64decode(found[DATA_ID.encode()][0], validate=True)
    except (ValueError, binascii.Error):
        raise InputError("the player file's data block is not valid base64 or JSON; the file is corrupt.") from None
    stated = re.search(rb'data-bytes="(\d+)"', found[DATA_ID.encode()][1])
    return meta, packed, int(stated.group(1)) if stated else -1


def _inflate(packed: bytes, limit: int) -> bytes:
    """Inflate at most limit bytes; InputError when the stream is corrupt, truncated or longer."""
    d = zlib.decompressobj()
    try:
        out = d.decompress(packed, limit + 1)
    except zlib.error:
        raise InputError("the player's data block does not inflate; the file is corrupt or truncated.") from None
    if len(out) != limit or not d.eof:
        raise InputError("the player's data block is truncated or longer than stated; the file is corrupt.")
    return out


def _take(buf: memoryview, pos: int, dtype: str, n: int) -> tuple[np.ndarray, int]:
    """n elements of a byte-planar section at pos, and the next section's position."""
    width = np.dtype(dtype).itemsize
    size = width * n
    if pos + size > len(buf):
        raise InputError("the player's data block ends early; the file is corrupt.")
    planes = np.frombuffer(buf, np.uint8, size, pos).reshape(width, n)
    return np.ascontiguousarray(planes.T).view(dtype).ravel().astype(np.int64), pos + size + (-size % 4)


def _unpack_keys(counts: np.ndarray, fd: np.ndarray, vd: np.ndarray, t: int, modulo: int = 0):
    """Inverse of _pack_keys: key track, frame (K,) and value (K, D), checked against T."""
    if counts.sum() != len(fd):
        raise InputError("the player's key counts do not add up; the file is corrupt.")
    track = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    fk, vals = np.cumsum(fd), np.cumsum(vd, axis=0)
    has = counts > 0
    base_f = np.repeat((fk - fd)[starts[has]], counts[has])
    base_v = np.repeat((vals - vd)[starts[has]], counts[has], axis=0)
    fk, vals = fk - base_f, vals - base_v
    if modulo:
        vals %= modulo
    step_ok = np.ones(len(fk), bool)
    step_ok[1:] = (fk[1:] > fk[:-1]) | (track[1:] != track[:-1])
    if len(fk) and (fk.max() > t or not step_ok.all()):
        raise InputError("the player's key frames are out of order or range; the file is corrupt.")
    return track, fk, vals


def _expand(track: np.ndarray, fk: np.ndarray, vals: np.ndarray, n: int, t1: int) -> np.ndarray:
    """Linear interpolation of keyed tracks at frames 0..t1-1: (t1, n, D); NaN for tracks without keys."""
    d = vals.shape[1]
    out = np.full((t1, n, d), np.nan)
    if not len(fk):
        return out
    counts = np.bincount(track, minlength=n)
    starts = np.cumsum(counts) - counts
    code = track * (t1 + 1) + fk
    has = np.flatnonzero(counts > 0)
    frames = np.arange(t1)
    q = (has[:, None] * (t1 + 1) + frames[None, :]).ravel()
    i = np.searchsorted(code, q, side="right") - 1
    lo = np.repeat(starts[has], t1)
    hi = np.repeat(starts[has] + counts[has] - 1, t1)
    i = np.clip(i, lo, hi)
    j = np.minimum(i + 1, hi)
    f = np.tile(frames, len(has))
    span = np.maximum(fk[j] - fk[i], 1)
    w = np.clip((f - fk[i]) / span, 0.0, 1.0)[:, None]
    v = vals[i] + w * (vals[j] - vals[i])
    out[:, has] = v.reshape(len(has), t1, d).transpose(1, 0, 2)
    return out


def decode(data: bytes) -> Decoded:
    """Decode a player HTML file to per-frame vertex positions, visibility and colours; InputError if corrupt."""
    meta, packed, stated = _blocks(data)
    if not 0 < stated <= 1 << 30:
        raise InputError("the player's data block states no valid length; the file is corrupt.")
    block = _inflate(packed, stated)
    if len(block) < HEADER.size:
        raise InputError("the player's data block is shorter than its header; the file is corrupt.")
    (magic, version, flags, t, fps, w, h, scale, n_v, p, n_pk, n_ct, n_ck, n_vc, size,
     crc) = HEADER.unpack_from(block)
    if magic != MAGIC or version != VERSION:
        raise InputError(f"the data block is not a version {VERSION} facesvg player block; regenerate the file.")
    payload = block[HEADER.size:]
    if size != len(payload) or zlib.crc32(payload) != crc:
        raise InputError("the player's data block fails its length or CRC-32 check; the file is corrupt.")
    if not 0 < t <= MAX_FRAMES or not fps > 0 or scale < 1 or (t + 1) * max(n_v, n_ct, p) * 3 > MAX_EXPANDED:
        raise InputError("the player's header holds impossible counts; the file is corrupt.")
    gouraud, wide = bool(flags & FLAG_GOURAUD), bool(flags & FLAG_WIDE)
    buf = memoryview(payload)
    pos = 0
    vertex_ids, pos = _take(buf, pos, "<u4", n_v)
    tris, pos = _take(buf, pos, "<u4", p)
    local, pos = _take(buf, pos, "<u4", 3 * p)
    vis0, pos = _take(buf, pos, "u1", p)
    vc, pos = _take(buf, pos, "<u2", p)
    vf, pos = _take(buf, pos, "<u2", n_vc)
    pc, pos = _take(buf, pos, "<u2", n_v)
    pf, pos = _take(buf, pos, "<u2", n_pk)
    pv, pos = _take(buf, pos, "<i4" if wide else "<i2", 2 * n_pk)
    cc, pos = _take(buf, pos, "<u2", n_ct)
    cf, pos = _take(buf, pos, "<u2", n_ck)
    cv, pos = _take(buf, pos, "u1", 3 * n_ck)
    mats = None
    if flags & FLAG_HEAD:
        width = 6 * (t + 1)
        if pos + 4 * width > len(payload):
            raise InputError("the player's data block ends early; the file is corrupt.")
        mats = np.frombuffer(payload, np.uint8, 4 * width, pos).reshape(4, width).T.copy().view("<f4")
        mats = mats.reshape(t + 1, 2, 3).astype(np.float64)
        pos += 4 * width
    if pos != len(payload) or n_ct != (n_v if gouraud else p):
        raise InputError("the player's sections do not fill its data block; the file is corrupt.")
    if len(local) and local.max() >= n_v:
        raise InputError("a path names a vertex the player does not store; the file is corrupt.")
    track, fk, vals = _unpack_keys(pc, pf, pv.reshape(-1, 2), t)
    xy = _expand(track, fk, vals.astype(np.float64) / scale, n_v, t + 1)
    if mats is not None:  # local to the head transform: to px
        xy = groups.apply_linear(mats[:, :, :2], xy) + mats[:, None, :, 2]
    ctrack, cfk, cvals = _unpack_keys(cc, cf, cv.reshape(-1, 3), t, modulo=256)
    rgb = _expand(ctrack, cfk, cvals.astype(np.float64), n_ct, t + 1)
    vtrack, vfk, _ = _unpack_keys(vc, vf, np.zeros((len(vf), 1), np.int64), t - 1)
    flips = np.zeros((t, p), np.int64)
    np.add.at(flips, (vfk, vtrack), 1)
    shown = (vis0[None, :] + np.cumsum(flips, axis=0)) % 2 == 1
    return Decoded(meta, t, fps, w, h, scale, gouraud, vertex_ids, tris, local.reshape(p, 3), xy, shown, rgb)
