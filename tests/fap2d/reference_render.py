"""Reference renderer of a fap2d package: the frames static/fap2d.js draws, in numpy + Pillow + scipy.

Used by tests/fap2d and bench/bench_fap2d.py (both put this folder on sys.path, as for player.py)."""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw
from scipy.ndimage import map_coordinates

from converter.errors import InputError


@dataclass(frozen=True, eq=False)
class FatEntry:
    """One FAP's 2D table: breakpoints (K,), vertex ids (n,), displacements (K, n or 1, 2) in px."""

    fap: int
    kind: str
    amplitudes: np.ndarray
    vertices: np.ndarray
    displacements: np.ndarray


@dataclass(frozen=True, eq=False)
class Fap2d:
    """A decoded package: layers, neutral 2D mesh, 2D FAT and the FAP stream values."""

    manifest: dict
    portrait: np.ndarray  # (H, W, 4) uint8
    mouth: np.ndarray  # (H, W, 4) uint8
    xy0: np.ndarray  # (N, 2) float64 neutral vertex positions = texture coordinates, px
    triangles: np.ndarray  # (F, 3) drawing order, back to front
    fat: tuple[FatEntry, ...]
    values: np.ndarray  # (T, 68) low-level FAP values of the stream
    overdraw: float
    dirty_cell: int
    mouth_box: tuple[int, int, int, int] | None

    @property
    def n_frames(self) -> int:
        """Frames in the stream."""
        return int(self.values.shape[0])


def _array(blob: bytes, ref: dict) -> np.ndarray:
    dt = np.dtype("<" + ref["dtype"])
    n = int(np.prod(ref["shape"])) if ref["shape"] else 1
    end = ref["offset"] + n * dt.itemsize
    if end > len(blob):
        raise InputError("the package's data.bin is shorter than its manifest says; the package is corrupt.")
    return np.frombuffer(blob, dt, n, ref["offset"]).reshape(ref["shape"])


def _image(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))


def load_package(data: bytes) -> Fap2d:
    """Decode a fap2d zip (as the player does)."""
    from converter.mpeg4.fap import read_fap

    try:
        z = zipfile.ZipFile(io.BytesIO(data))
        files = {n: z.read(n) for n in z.namelist()}
    except (zipfile.BadZipFile, KeyError) as exc:
        raise InputError(f"not a fap2d package (zip): {exc}.") from None
    if "manifest.json" not in files:
        raise InputError("the zip has no manifest.json; it is not a fap2d package.")
    m = json.loads(files["manifest.json"])
    blob = files[m["data"]]
    mesh = m["mesh"]
    xy0 = _array(blob, mesh["vertices"]).astype(np.float64) * mesh["xy_step"]
    tri = _array(blob, mesh["triangles"]).astype(np.int64)
    fat = []
    for e in m["fat2d"]["faps"]:
        amps = np.array(e["amplitudes"], np.float64)
        disp = _array(blob, e["displacements"]).astype(np.float64) * e["step_px"]
        at = int(np.searchsorted(amps, 0.0))  # the table passes through 0 at amplitude 0
        fat.append(FatEntry(e["fap"], e["kind"], np.insert(amps, at, 0.0), _array(blob, e["vertices"]).astype(np.int64),
                            np.insert(disp, at, 0.0, axis=0)))
    fat = tuple(fat)
    stream = read_fap(files[m["stream"]["file"]].decode())
    layers = {layer["name"]: layer for layer in m["layers"]}
    box = layers["mouth"].get("box")
    return Fap2d(m, _image(files[layers["portrait"]["image"]]), _image(files[layers["mouth"]["image"]]), xy0, tri, fat,
                 stream.low_level(), float(mesh.get("overdraw_px", 0.0)), int(mesh["dirty_cell_px"]),
                 tuple(box) if box else None)


def interpolate(amplitudes: np.ndarray, table: np.ndarray, value: float) -> np.ndarray:
    """Piecewise-linear table lookup at value, extrapolating the end segments: (K, ...) -> (...)."""
    k = len(amplitudes)
    i = int(np.clip(np.searchsorted(amplitudes, value, side="right") - 1, 0, k - 2))
    t = (value - amplitudes[i]) / (amplitudes[i + 1] - amplitudes[i])
    return table[i] + t * (table[i + 1] - table[i])


def positions(pkg: Fap2d, values: np.ndarray) -> np.ndarray:
    """2D vertex positions (N, 2) under one frame's 68 FAP values."""
    xy = pkg.xy0.copy()
    for e in pkg.fat:
        v = float(values[e.fap - 1])
        if v != 0.0:
            xy[e.vertices] += interpolate(e.amplitudes, e.displacements, v)
    return xy


def _over(dst: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Premultiplied 'source over'."""
    return src + dst * (1.0 - src[..., 3:4])


def _premultiplied(rgba: np.ndarray) -> np.ndarray:
    f = rgba.astype(np.float64) / 255.0
    f[..., :3] *= f[..., 3:4]
    return f


MITER_LIMIT = 4.0  # a grown corner moves at most this many times the growth


def expanded(tri_xy: np.ndarray, amount: float) -> np.ndarray:
    """Triangles (F, 3, 2) with every edge pushed `amount` px outwards (mitred corners, limited): the overlap
    that hides anti-aliased seams between neighbours, even along thin triangles."""
    if amount <= 0:
        return tri_xy
    p = tri_xy
    e = np.roll(p, -1, axis=1) - p  # edge i runs from corner i to corner i+1
    n = np.stack([e[..., 1], -e[..., 0]], axis=-1)
    ln = np.linalg.norm(n, axis=-1, keepdims=True)
    n = n / np.where(ln > 1e-12, ln, 1.0)
    inward = (n * (np.roll(p, -2, axis=1) - p)).sum(-1) > 0  # points towards the opposite corner
    n = np.where(inward[..., None], -n, n)
    na = np.roll(n, 1, axis=1)  # the other edge at corner i
    denom = 1.0 + (na * n).sum(-1, keepdims=True)
    m = (na + n) / np.where(denom > 1e-6, denom, 1e-6)
    length = np.linalg.norm(m, axis=-1, keepdims=True)
    m = m * np.minimum(1.0, MITER_LIMIT / np.where(length > 0, length, 1.0))
    return p + amount * m


DIRTY_MARGIN = 2.0  # px around a box when finding its cells (covers the overdraw)


def drawn_triangles(pkg: Fap2d, xy: np.ndarray) -> np.ndarray:
    """Bool (F,): the triangles a frame draws. One that no FAP moves, away from every moved triangle (old and
    new place) and from the mouth layer, would draw the portrait's own pixels, so players skip it."""
    h, w = pkg.portrait.shape[:2]
    c = pkg.dirty_cell
    gw, gh = -(-w // c), -(-h // c)
    tri = pkg.triangles
    moving = (xy != pkg.xy0).any(axis=1)[tri].any(axis=1)
    src = pkg.xy0[tri]
    both = np.concatenate([src, xy[tri]], axis=1)
    lo = np.floor((both.min(axis=1) - DIRTY_MARGIN) / c).astype(np.int64)
    hi = np.floor((both.max(axis=1) + DIRTY_MARGIN) / c).astype(np.int64)
    lo = np.clip(lo, 0, [gw - 1, gh - 1])
    hi = np.clip(hi, 0, [gw - 1, gh - 1])
    dirty = np.zeros((gh, gw), bool)
    boxes = [(*lo[i], *hi[i]) for i in np.flatnonzero(moving)]
    if pkg.mouth_box is not None:
        x0, y0, x1, y1 = pkg.mouth_box
        boxes.append((int(np.floor((x0 - DIRTY_MARGIN) / c)), int(np.floor((y0 - DIRTY_MARGIN) / c)),
                      int(np.floor((x1 + DIRTY_MARGIN) / c)), int(np.floor((y1 + DIRTY_MARGIN) / c))))
    for x0, y0, x1, y1 in boxes:
        dirty[max(y0, 0):min(y1, gh - 1) + 1, max(x0, 0):min(x1, gw - 1) + 1] = True
    sat = np.zeros((gh + 1, gw + 1), np.int64)  # summed-area table: any dirty cell under a box in O(1)
    sat[1:, 1:] = dirty.cumsum(0).cumsum(1)
    x0, y0, x1, y1 = lo[:, 0], lo[:, 1], hi[:, 0] + 1, hi[:, 1] + 1
    touched = (sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0]) > 0
    return moving | touched


def render_positions(pkg: Fap2d, xy: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: portrait, then mouth layer, then the mesh warped to xy (textured by the portrait)."""
    h, w = pkg.portrait.shape[:2]
    dst = xy[pkg.triangles]  # (F, 3, 2)
    src = pkg.xy0[pkg.triangles]
    d_mat = np.concatenate([dst.transpose(0, 2, 1), np.ones((len(dst), 1, 3))], axis=1)  # (F, 3, 3) columns = corners
    det = np.linalg.det(d_mat)
    ok = (np.abs(det) > 1e-9) & drawn_triangles(pkg, xy)
    affine = np.zeros((len(dst), 2, 3))
    affine[ok] = src.transpose(0, 2, 1)[ok] @ np.linalg.inv(d_mat[ok])  # pixel -> texture coordinates
    ids = Image.new("I", (w, h), 0)
    draw = ImageDraw.Draw(ids)
    grown = expanded(dst, pkg.overdraw)
    for i in np.flatnonzero(ok):
        draw.polygon([tuple(p) for p in grown[i]], fill=int(i) + 1)
    idmap = np.asarray(ids, np.int64)
    ys, xs = np.nonzero(idmap)
    a = affine[idmap[ys, xs] - 1]
    px = np.stack([xs + 0.5, ys + 0.5, np.ones(len(xs))], axis=1)
    uv = np.einsum("nij,nj->ni", a, px) - 0.5  # texture pixel-centre coordinates
    tex = _premultiplied(pkg.portrait)
    layer = np.zeros((h, w, 4))
    for c in range(4):
        layer[ys, xs, c] = map_coordinates(tex[..., c], [uv[:, 1], uv[:, 0]], order=1, mode="constant", cval=0.0)
    out = _over(_over(_premultiplied(pkg.portrait), _premultiplied(pkg.mouth)), layer)
    alpha = out[..., 3:4]
    rgb = np.where(alpha > 0, out[..., :3] / np.where(alpha > 0, alpha, 1.0), 0.0)
    return np.round(np.concatenate([rgb, alpha], axis=-1) * 255).clip(0, 255).astype(np.uint8)


def render_frame(pkg: Fap2d, values: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 frame for one row of 68 FAP values."""
    return render_positions(pkg, positions(pkg, np.asarray(values, np.float64)))


def render_stream_frame(pkg: Fap2d, k: int) -> np.ndarray:
    """(H, W, 4) uint8 frame k of the package's own stream."""
    if not 0 <= k < pkg.n_frames:
        raise InputError(f"frame {k} is outside 0..{pkg.n_frames - 1}.")
    return render_frame(pkg, pkg.values[k])
