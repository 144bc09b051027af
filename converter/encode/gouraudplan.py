"""The Gouraud SVG's plan: drawing order, seam strokes, every triangle's gradient signals and their keys.

What converter.writers.svg_gouraud spells (its module docstring has the two methods): per triangle and frame the
numbers of its attributes (``Signals``: the path's corners, the gradient axis ends and stop colours of the exact
one-gradient fit, or the chapter's three vertex ramps and average colour), keyed within one error budget
(geometry and colour each with keys of their own, colours in levels scaled into px-equivalent units), the seam
strokes (seams.py: which edge each path leaves open, and the frames where a stroke would spill past the outline),
and for a still of the exact method the per-part underlay that covers cracks at folds.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from PIL import Image, ImageDraw

from converter.arrays import painter_order
from converter.encode import keys as keyframes
from converter.encode import seams
from converter.encode.gradients import LinearGradients, exact_gradients, vertex_ramps
from converter.options import ConversionOptions, Progress, no_progress, span
from converter.sheet import Sheet

ROUNDING_PX = 0.005  # coordinates are written with 2 decimals
GRADIENT_FRAMES = 32  # frames whose gradients are fitted together
COLOR_EPS_LEVELS = 1.5  # 8-bit levels a keyframed stop colour may deviate before rounding (+0.5 from rounding)
UNDERLAY = True  # stills of the exact method get a seamless per-part underlay
UNDERLAY_INSET = 0.5  # px the underlay stays inside the silhouette
SEAM_STROKE = 1.0  # px of same-paint stroke over interior edges: covers anti-aliasing cracks (exact method);
# stroke-width 0 at the frames where it would reach past the outline (seams.stroke_off)


class Track(NamedTuple):
    """One attribute's columns of the signal matrix, and the scale from its units to the error units."""

    cols: slice
    scale: float = 1.0
    color: bool = False  # 8-bit colour levels (keyed with the colour group), else px


class Signals:
    """Every numeric attribute of every triangle over the frames: (T, K, D) plus the tracks naming the columns."""

    def __init__(self) -> None:
        self.blocks: list[np.ndarray] = []
        self.tracks: dict[str, Track] = {}
        self.width = 0

    def add(self, key: str, data: np.ndarray, scale: float = 1.0, color: bool = False) -> None:
        """Register a track whose per-frame values are data (T, K, n), scaled into the signal's error units."""
        data = data.reshape(data.shape[0], data.shape[1], int(np.prod(data.shape[2:], dtype=int))) * scale
        cols = slice(self.width, self.width + data.shape[2])
        self.width += data.shape[2]
        self.blocks.append(data)
        self.tracks[key] = Track(cols, scale, color)

    def matrix(self) -> np.ndarray:
        """All tracks side by side, (T, K, D)."""
        return np.concatenate(self.blocks, axis=2)


class GouraudPlan(NamedTuple):
    """What svg_gouraud spells (see ``plan``)."""

    method: str  # 'exact' or 'chapter'
    frame: int | None  # the still's frame, or None for the animation
    order: np.ndarray  # int (K,) triangles back to front
    closed: np.ndarray  # bool (K,) the path is closed (else it leaves its one outline edge open)
    stroked: np.ndarray  # bool (K,) the path has the seam stroke
    stroke_off: np.ndarray | None  # bool (T, K) frames where a stroke would spill past the outline (animation)
    signals: Signals
    values: np.ndarray  # (T, K, D) the signals' values in error units
    keys: dict[bool, tuple[np.ndarray, np.ndarray]] | None  # per group (colour?) keys (mask (T+1, K), values
    # (T+1, K, D)), None for a still
    underlay: list[tuple[np.ndarray, np.ndarray]]  # per part: inset triangles (n, 3, 2) px and its colour levels (3,)
    residual_max: float | None  # the exact fit's largest rank-1 residual over shown triangles (exact method)
    n_keys: int | None  # keys written (None: every frame, or a still)


def signals_exact(tri_xy: np.ndarray, tri_rgb: np.ndarray, color_scale: float,
                  progress: Progress = no_progress) -> tuple[Signals, np.ndarray]:
    """Signals of the exact method and the per-frame rank-1 residual (T, K); the gradients a block of
    GRADIENT_FRAMES frames at a time (each triangle and frame is its own fit: the same values), with progress."""
    t = tri_xy.shape[0]
    parts = []
    for a in range(0, t, GRADIENT_FRAMES):
        progress("signals", a / max(t, 1))
        parts.append(exact_gradients(tri_xy[a:a + GRADIENT_FRAMES], tri_rgb[a:a + GRADIENT_FRAMES]))
    g = LinearGradients(*(np.concatenate(f) for f in zip(*parts))) if len(parts) != 1 else parts[0]
    s = Signals()
    s.add("d", tri_xy)
    for key, arr in (("x1", g.start[..., 0]), ("y1", g.start[..., 1]), ("x2", g.end[..., 0]), ("y2", g.end[..., 1])):
        s.add(key, arr)
    s.add("c1", g.start_rgb * 255, color_scale, color=True)
    s.add("c2", g.end_rgb * 255, color_scale, color=True)
    return s, g.residual


def signals_chapter(tri_xy: np.ndarray, tri_rgb: np.ndarray, color_scale: float) -> Signals:
    """Signals of the chapter method: three vertex ramps, their colours, and the average-colour background."""
    start, foot = vertex_ramps(tri_xy)
    s = Signals()
    s.add("d", tri_xy)
    s.add("bg", tri_rgb.mean(axis=-2) * 255, color_scale, color=True)
    for i in range(3):
        s.add(f"x1{i}", start[..., i, 0])
        s.add(f"y1{i}", start[..., i, 1])
        s.add(f"x2{i}", foot[..., i, 0])
        s.add(f"y2{i}", foot[..., i, 1])
        s.add(f"c{i}", tri_rgb[..., i, :] * 255, color_scale, color=True)
    return s


def hold_colours_in_range(mask: np.ndarray, values: np.ndarray, active: np.ndarray,
                          signals: Signals) -> tuple[np.ndarray, np.ndarray]:
    """End keys extrapolated past 0..255 cannot be written as colours: key the last active frame and hold it.

    The new key takes the old segment's value there with colours clipped; as the true colour lies in 0..255
    and within eps of that value, clipping only moves it closer, and earlier frames move by at most eps more.
    """
    t = active.shape[0]
    cols = np.zeros(values.shape[2], bool)
    hi = np.zeros(values.shape[2])
    for tr in signals.tracks.values():
        if tr.color:
            cols[tr.cols] = True
            hi[tr.cols] = 255 * tr.scale
    end = values[t]
    bad = (((end < 0) | (end > hi)) & cols).any(axis=1) & mask[t]
    for j in np.flatnonzero(bad).tolist():
        last = int(np.flatnonzero(active[:, j])[-1])
        kt = np.flatnonzero(mask[:, j])
        line = np.array([np.interp(last, kt, values[kt, j, c]) for c in range(values.shape[2])])
        line = np.where(cols, np.clip(line, 0, hi), line)
        mask[last, j] = True
        values[last, j] = line
        values[t, j] = line
    return mask, values


def outline_edges(tris: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
    """Bool (K, 3): edge i (vertex i to i+1) belongs to no other of the triangles (vertices compared by ids)."""
    tris = np.asarray(tris, np.int64)
    welded = tris if ids is None else np.asarray(ids, np.int64)[tris]
    a, b = welded, np.roll(welded, -1, axis=1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    code = lo * (int(welded.max(initial=0)) + 1) + hi
    _, inv, counts = np.unique(code.reshape(-1), return_inverse=True, return_counts=True)
    return (counts[inv] < 2).reshape(tris.shape)


def silhouette_edges(tri_xy: np.ndarray, outline: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bool (K, 3): outline edges with nothing drawn just beyond them (the outer silhouette, not a fold).

    Where a surface folds away the edge has no neighbour, yet another drawn surface continues beyond it: a
    crack there shows the page unless something lies under it. Decided on a 2x raster of the drawn union.
    """
    scale = 2
    img = Image.new("1", (width * scale, height * scale), 0)
    draw = ImageDraw.Draw(img)
    for t in (tri_xy.reshape(-1, 6) * scale).tolist():
        draw.polygon(t, fill=1)
    covered = np.asarray(img, bool)
    a = tri_xy
    b = np.roll(tri_xy, -1, axis=1)
    c = np.roll(tri_xy, -2, axis=1)  # the vertex opposite edge i
    edge = b - a
    normal = np.stack([edge[..., 1], -edge[..., 0]], axis=-1)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    normal *= np.sign(((a - c) * normal).sum(axis=-1, keepdims=True) + 1e-12)  # point away from the triangle
    beyond = []
    for f in (0.25, 0.5, 0.75):
        p = (a + f * edge + 1.5 * normal) * scale
        x = np.clip(p[..., 0].astype(int), 0, width * scale - 1)
        y = np.clip(p[..., 1].astype(int), 0, height * scale - 1)
        beyond.append(covered[y, x])
    return outline & ~np.any(beyond, axis=0)


def seam_layout(tris: np.ndarray, skip: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the anti-crack stroke goes: (rotated triangles (K, 3), closed (K,), stroked (K,)).

    `skip` (K, 3) marks edges not to stroke: outline edges (seams.skips: no drawn neighbour at some frame), where a
    stroke would fatten the silhouette or spill over an occluding contour (a still's underlay covers cracks at
    folds instead). A triangle with one such edge is listed starting after it and written as an open path: fill
    closes it implicitly, the stroke skips it. One with two or three is not stroked; its other edges are left to
    the neighbours' strokes.
    """
    tris = np.asarray(tris, np.int64)
    n_out = skip.sum(axis=1)
    start = np.where(n_out == 1, (np.argmax(skip, axis=1) + 1) % 3, 0)
    idx = (start[:, None] + np.arange(3)[None]) % 3
    rotated = np.take_along_axis(tris, idx, axis=1).astype(np.int32)
    return rotated, n_out != 1, n_out <= 1


def underlay(tri_xy: np.ndarray, tri_rgb: np.ndarray, part_ids: np.ndarray,
             silhouette: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per part, its triangles (K, 3, 2) as one shape in the part's mean colour (levels (3,)), to go under a still.

    A single path's coverage is computed for the union, so it has no internal seams: wherever anti-aliased
    neighbours leave a pixel partly uncovered, this colour shows instead of the page. Silhouette edges are
    pulled in by UNDERLAY_INSET px so the outline keeps the triangles' own anti-aliasing.
    """
    xy = np.array(tri_xy, np.float64)
    for i in range(3):
        a, b, c = xy[:, i], xy[:, (i + 1) % 3], xy[:, (i + 2) % 3]
        edge = b - a
        length = np.linalg.norm(edge, axis=-1)
        height = np.abs(edge[:, 0] * (c - a)[:, 1] - edge[:, 1] * (c - a)[:, 0]) / np.maximum(length, 1e-12)
        k = np.where(silhouette[:, i], np.clip(1 - UNDERLAY_INSET / np.maximum(height, 1e-12), 0, 1), 1.0)
        xy[:, i] = c + (a - c) * k[:, None]  # scale about the opposite vertex: the edge moves in, parallel
        xy[:, (i + 1) % 3] = c + (b - c) * k[:, None]
    out = []
    for part in np.unique(part_ids).tolist():
        sel = part_ids == part
        rgb = np.clip(np.round(tri_rgb[sel].reshape(-1, 3).mean(axis=0) * 255), 0, 255).astype(int)
        out.append((xy[sel], rgb))
    return out


def plan(sheet: Sheet, options: ConversionOptions, progress: Progress = no_progress) -> GouraudPlan:
    """The Gouraud plan of options.frame's still, else of the animation; progress(stage, fraction) up to 0.6."""
    method = "chapter" if options.shading == "gouraud-chapter" else "exact"
    t_all = sheet.n_frames
    still = options.frame is not None
    w, h = sheet.camera.width, sheet.camera.height
    if still:
        k = int(options.frame)
        cand = sheet.order[sheet.visible[k, sheet.order]]
        order = painter_order(sheet.depth, sheet.faces, cand, k)  # the still's own depth order
        frames = np.array([k])
    else:
        order = sheet.order
        frames = np.arange(t_all)
    silhouette = None
    stroke_off: np.ndarray | None = None
    if method == "exact":
        tris = sheet.faces[order]
        drawn = np.take(sheet.visible[frames], order, axis=1)
        corners = seams.welded_ids(sheet.xy[frames], sheet.depth[frames])[tris]
        skip, _ = seams.skips(corners, drawn, sheet.xy[frames], tris, SEAM_STROKE / 2)
        if not still:  # the layout is one for all frames: a stroke that would spill at a frame is off there
            stroke_off = seams.stroke_off(corners, drawn, skip, sheet.xy[frames], tris, SEAM_STROKE / 2)
        if still:  # the underlay keeps off the outer silhouette but covers folds (outline edges with surface beyond)
            silhouette = silhouette_edges(sheet.xy[frames[0]][tris].astype(np.float64), skip, w, h)
        tri, closed, stroked = seam_layout(tris, skip)
    else:  # the chapter draws no strokes: its background triangles are its answer to cracks
        tri, closed, stroked = sheet.faces[order], np.ones(len(order), bool), np.zeros(len(order), bool)
    progress("signals", 0.05)
    tri_xy = np.take(sheet.xy[frames], tri, axis=1).astype(np.float64)  # (T, K, 3, 2)
    tri_rgb = np.take(sheet.vertex_rgb[frames], tri, axis=1).astype(np.float64)  # (T, K, 3, 3)
    eps = max(options.tolerance - ROUNDING_PX, ROUNDING_PX)
    color_scale = eps / COLOR_EPS_LEVELS  # colour levels -> px-equivalent units, so one eps bounds both
    active = np.take(sheet.visible[frames], order, axis=1)
    residual_max = None
    if method == "exact":
        signals, residual = signals_exact(tri_xy, tri_rgb, color_scale, span(progress, 0.05, 0.5))
        residual_max = float(residual[active].max()) if active.any() else 0.0
    else:
        signals = signals_chapter(tri_xy, tri_rgb, color_scale)
    x = signals.matrix()
    progress("keys", 0.55)  # the signals (gradients of every triangle and frame) take about as long as the rest
    keys: dict[bool, tuple[np.ndarray, np.ndarray]] | None = None
    n_keys = None
    if options.raw and not still:
        every = (np.ones((t_all + 1, len(order)), bool), np.concatenate([x, x[-1:]], axis=0))
        keys = {False: every, True: every}
    elif not still:
        # Geometry and colour get keys of their own: shading often changes more slowly than the mesh moves.
        keys = {}
        is_color = np.zeros(x.shape[2], bool)
        for tr in signals.tracks.values():
            is_color[tr.cols] = tr.color
        for group in (False, True):
            cols = np.flatnonzero(is_color == group)
            reduced = keyframes.reduce(x[..., cols], active, eps)
            values = np.zeros((t_all + 1,) + x.shape[1:])
            values[..., cols] = reduced.values
            keys[group] = (reduced.mask, values)
            progress("keys", 0.6 if group else 0.575)  # geometry, then colour: about the same work
        keys[True] = hold_colours_in_range(*keys[True], active, signals)
        n_keys = int(sum(m.sum() for m, _ in keys.values()))
    under = []
    if still and method == "exact" and UNDERLAY:
        k = int(options.frame)
        under = underlay(sheet.xy[k][sheet.faces[order]], sheet.vertex_rgb[k][sheet.faces[order]],
                         sheet.part_ids[order], silhouette)
    return GouraudPlan(method, int(options.frame) if still else None, order, closed, stroked, stroke_off, signals, x,
                       keys, under, residual_max, n_keys)
