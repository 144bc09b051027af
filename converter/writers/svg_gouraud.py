"""Gouraud-shaded SVG: the exact one-gradient method ('gouraud') and the chapter's three-gradient filter method.

Colour space: the Sheet's vertex colours are display (sRGB-encoded) values. The pyrender prerender writes them
unchanged (FLAT shader, no sRGB framebuffer) and interpolates them linearly, and SVG gradients interpolate in
sRGB by default (color-interpolation="sRGB"), so both interpolate the same numbers. Filters default to
linearRGB, so the chapter method's filters say color-interpolation-filters="sRGB" or their sum would be wrong.

A gradient's axis animations sit beside it (``<animate href="#g7">``), never inside: CairoSVG reads every child
of a gradient as a stop (black, offset 0), which drew black seams along many edges of frame 0.
"""

from __future__ import annotations

from xml.sax.saxutils import escape

import numpy as np
from PIL import Image, ImageDraw

from converter.encode import keys as keyframes
from converter.encode import seams
from converter.errors import InputError
from converter.extract import painter_order
from converter.options import ConversionOptions, Progress, Report, no_progress, span
from converter.sheet import Sheet
from converter.writers import svg_anim
from converter.writers.gradients import LinearGradients, exact_gradients, vertex_ramps
from converter.writers.svgtext import key_times
from converter.writers.svgtext import number as svg_number

PATH_FMT = "M%.2f,%.2fL%.2f,%.2fL%.2f,%.2f"  # open: "Z" is added where every edge is stroked
COORD_FMT = "%.2f"
UNDERLAY_FMT = "M%.1f,%.1fL%.1f,%.1fL%.1f,%.1fZ"
COLOR_FMT = "#%06x"
ROUNDING_PX = 0.005  # coordinates are written with 2 decimals
GOURAUD_PROGRESS = 1024  # triangles written between progress reports
GRADIENT_FRAMES = 32  # frames whose gradients are fitted together
COLOR_EPS_LEVELS = 1.5  # 8-bit levels a keyframed stop colour may deviate before rounding (+0.5 from rounding)
UNDERLAY = True  # stills of the exact method get a seamless per-part underlay
UNDERLAY_INSET = 0.5  # px the underlay stays inside the silhouette
SEAM_STROKE = 1.0  # px of same-paint stroke over interior edges: covers anti-aliasing cracks (exact method);
# stroke-width 0 at the frames where it would reach past the outline (seams.stroke_off)
# Opacity correction of the chapter's sum of three 8-bit layers: up to 1.5/255 of alpha lost to rounding.
CHAPTER_ALPHA_GAIN = 1 + 2 / 255
CHAPTER_FILTER = (
    '<filter id="x{f}" color-interpolation-filters="sRGB">'
    # x/y/width/height pin feImage's subregion to user space: the default (the filter region) shifts the
    # referenced triangle by the region's origin in Chromium and resvg.
    '<feImage href="#p{f}" x="0" y="0" width="100%" height="100%" result="a"/>'
    '<feImage href="#q{f}" x="0" y="0" width="100%" height="100%" result="b"/>'
    '<feComposite in="a" in2="b" operator="arithmetic" k2="1" k3="1" result="ab"/>'
    '<feComposite in="ab" in2="SourceGraphic" operator="arithmetic" k2="1" k3="1"/>'
    '<feColorMatrix values="1 0 0 0 0 0 1 0 0 0 0 0 1 0 0 0 0 0 {gain} 0"/></filter>'
)




def _key_times(frames: np.ndarray, n_frames: int, floor: bool) -> str:
    """keyTimes attribute text for frame indices (frame k at k / T); floor for discrete changes so frame k sees
    its value."""
    return ";".join(key_times(frames, n_frames, len(str(n_frames)) + 2, "floor" if floor else "nearest"))


class _Track:
    """One attribute of one element: a printf format over columns of the per-triangle signal matrix."""

    def __init__(self, name: str, fmt: str, cols: slice, scale: float = 1.0, color: bool = False) -> None:
        self.name, self.fmt, self.cols, self.scale, self.color = name, fmt, cols, scale, color

    def texts(self, values: np.ndarray, suffix: str = "") -> list[str]:
        """Attribute text of each row of signal values (n, D), each followed by suffix."""
        v = values[:, self.cols] / self.scale
        if self.color:
            q = np.clip(np.round(v), 0, 255).astype(np.int64)
            return [COLOR_FMT % c for c in ((q[:, 0] << 16) | (q[:, 1] << 8) | q[:, 2]).tolist()]
        return [self.fmt % tuple(r) + suffix for r in v.tolist()]


class _Signals:
    """Every numeric attribute of every triangle over the frames: (T, K, D) plus the tracks naming the columns."""

    def __init__(self) -> None:
        self.blocks: list[np.ndarray] = []
        self.tracks: dict[str, _Track] = {}
        self.width = 0

    def add(self, key: str, name: str, fmt: str, data: np.ndarray, scale: float = 1.0, color: bool = False) -> None:
        """Register a track whose per-frame values are data (T, K, n), scaled into the signal's error units."""
        data = data.reshape(data.shape[0], data.shape[1], int(np.prod(data.shape[2:], dtype=int))) * scale
        cols = slice(self.width, self.width + data.shape[2])
        self.width += data.shape[2]
        self.blocks.append(data)
        self.tracks[key] = _Track(name, fmt, cols, scale, color)

    def matrix(self) -> np.ndarray:
        """All tracks side by side, (T, K, D)."""
        return np.concatenate(self.blocks, axis=2)


def _signals_exact(tri_xy: np.ndarray, tri_rgb: np.ndarray, color_scale: float,
                   progress: Progress = no_progress) -> tuple[_Signals, np.ndarray]:
    """Signals of the exact method and the per-frame rank-1 residual (T, K); the gradients a block of
    GRADIENT_FRAMES frames at a time (each triangle and frame is its own fit: the same values), with progress."""
    t = tri_xy.shape[0]
    parts = []
    for a in range(0, t, GRADIENT_FRAMES):
        progress("signals", a / max(t, 1))
        parts.append(exact_gradients(tri_xy[a:a + GRADIENT_FRAMES], tri_rgb[a:a + GRADIENT_FRAMES]))
    g = LinearGradients(*(np.concatenate(f) for f in zip(*parts))) if len(parts) != 1 else parts[0]
    s = _Signals()
    s.add("d", "d", PATH_FMT, tri_xy)
    for key, arr in (("x1", g.start[..., 0]), ("y1", g.start[..., 1]), ("x2", g.end[..., 0]), ("y2", g.end[..., 1])):
        s.add(key, key, COORD_FMT, arr)
    s.add("c1", "stop-color", COLOR_FMT, g.start_rgb * 255, color_scale, color=True)
    s.add("c2", "stop-color", COLOR_FMT, g.end_rgb * 255, color_scale, color=True)
    return s, g.residual


def _signals_chapter(tri_xy: np.ndarray, tri_rgb: np.ndarray, color_scale: float) -> _Signals:
    """Signals of the chapter method: three vertex ramps, their colours, and the average-colour background."""
    start, foot = vertex_ramps(tri_xy)
    s = _Signals()
    s.add("d", "d", PATH_FMT, tri_xy)
    s.add("bg", "fill", COLOR_FMT, tri_rgb.mean(axis=-2) * 255, color_scale, color=True)
    for i in range(3):
        s.add(f"x1{i}", "x1", COORD_FMT, start[..., i, 0])
        s.add(f"y1{i}", "y1", COORD_FMT, start[..., i, 1])
        s.add(f"x2{i}", "x2", COORD_FMT, foot[..., i, 0])
        s.add(f"y2{i}", "y2", COORD_FMT, foot[..., i, 1])
        s.add(f"c{i}", "stop-color", COLOR_FMT, tri_rgb[..., i, :] * 255, color_scale, color=True)
    return s


class _Emit:
    """Per-triangle attribute text: a still (one row of values) or SMIL animations through the triangle's keys.

    Animated tracks come in groups (geometry, colour), each with its own keys: (mask (T+1, K), values (T+1, K, D)).
    """

    def __init__(self, signals: _Signals, values: np.ndarray, keys: dict[bool, tuple[np.ndarray, np.ndarray]] | None,
                 n_frames: int, dur: str) -> None:
        self.tracks, self.values, self.keys, self.t, self.dur = signals.tracks, values, keys, n_frames, dur
        self.closed = True
        self.rows: dict[bool, np.ndarray] = {}
        self.key_times: dict[bool, str] = {}

    def select(self, j: int, closed: bool = True) -> bool:
        """Work on triangle column j (its keys, keyTimes and key values); False when it is never shown."""
        self.closed = closed
        if self.keys is None:
            self.rows = {False: self.values[:1, j], True: self.values[:1, j]}
            return True
        for group, (mask, values) in self.keys.items():
            kt = np.flatnonzero(mask[:, j])
            if len(kt) == 0:
                return False
            self.rows[group] = values[kt, j]
            self.key_times[group] = _key_times(kt, self.t, floor=False)
        return True

    def attrs(self, *names: str, target: str = "") -> tuple[str, str]:
        """(attributes text, animate children) of the named tracks for the selected triangle; with target, the
        animations name their element by href instead (to be written beside it, not inside)."""
        a, kids = [], []
        href = f'href="#{target}" ' if target else ""
        for n in names:
            tr = self.tracks[n]
            texts = tr.texts(self.rows[tr.color], "Z" if n == "d" and self.closed else "")
            a.append(f'{tr.name}="{texts[0]}"')
            if self.keys is not None and any(x != texts[0] for x in texts):
                kids.append(
                    f'<animate {href}attributeName="{tr.name}" dur="{self.dur}" repeatCount="indefinite" '
                    f'keyTimes="{self.key_times[tr.color]}" values="{";".join(texts)}"/>'
                )
        return " ".join(a), "".join(kids)


def _hold_colours_in_range(mask: np.ndarray, values: np.ndarray, active: np.ndarray,
                           signals: _Signals) -> tuple[np.ndarray, np.ndarray]:
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


def welded_ids(xy: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(V,) one id per group of vertices that coincide in every frame given (xy (T, V, 2), depth (T, V)):
    seams.welded_ids."""
    return seams.welded_ids(xy, depth)


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
    folds instead). A
    triangle with one such edge is listed starting after it and written as an open path: fill closes it
    implicitly, the stroke skips it. One with two or three is not stroked; its other edges are left to the
    neighbours' strokes.
    """
    tris = np.asarray(tris, np.int64)
    n_out = skip.sum(axis=1)
    start = np.where(n_out == 1, (np.argmax(skip, axis=1) + 1) % 3, 0)
    idx = (start[:, None] + np.arange(3)[None]) % 3
    rotated = np.take_along_axis(tris, idx, axis=1).astype(np.int32)
    return rotated, n_out != 1, n_out <= 1


def underlay(tri_xy: np.ndarray, tri_rgb: np.ndarray, part_ids: np.ndarray, silhouette: np.ndarray) -> list[str]:
    """Per part, one path holding all its triangles (K, 3, 2) in the part's mean colour, to go under a still.

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
        d = "".join(UNDERLAY_FMT % tuple(t) for t in xy[sel].reshape(-1, 6).tolist())
        out.append(f'<path d="{d}" fill="#{rgb[0]:02x}{rgb[1]:02x}{rgb[2]:02x}"/>')
    return out


def _element(tag: str, attrs: str, body: str) -> str:
    return f"<{tag} {attrs}>{body}</{tag}>" if body else f"<{tag} {attrs}/>"


def _exact_triangle(e: _Emit, f: int, vis: tuple[str, str], stroked: bool | tuple[str, str]) -> str:
    """A userSpaceOnUse linearGradient along the colour gradient and the triangle filled and stroked with it."""
    axis, axis_anim = e.attrs("x1", "y1", "x2", "y2", target=f"g{f}")
    c1, c1_anim = e.attrs("c1")
    c2, c2_anim = e.attrs("c2")
    d, d_anim = e.attrs("d")
    stops = _element("stop", c1, c1_anim) + _element("stop", 'offset="1" ' + c2, c2_anim)
    grad = f'<linearGradient id="g{f}" gradientUnits="userSpaceOnUse" {axis}>{stops}</linearGradient>{axis_anim}'
    width = stroked if isinstance(stroked, tuple) else ("", "")
    stroke = f' stroke="url(#g{f})"{width[0]}' if stroked else ""
    path = _element("path", f'{d} fill="url(#g{f})"{stroke}{vis[0]}', d_anim + vis[1] + width[1])
    return grad + path


def _chapter_triangle(e: _Emit, f: int, vis: tuple[str, str], stroked: bool) -> str:
    """The chapter's Gouraud triangle: background, three alpha ramps, two feImage copies summed by a filter."""
    d, d_anim = e.attrs("d")
    bg, bg_anim = e.attrs("bg")
    out = [_element("path", f"{d} {bg}{vis[0]}", d_anim + bg_anim + vis[1])]
    for i, gid in enumerate("abc"):
        axis, axis_anim = e.attrs(f"x1{i}", f"y1{i}", f"x2{i}", f"y2{i}", target=f"{gid}{f}")
        c, c_anim = e.attrs(f"c{i}")
        stops = _element("stop", c, c_anim) + _element("stop", 'offset="1" stop-opacity="0" ' + c, c_anim)
        out.append(
            f'<linearGradient id="{gid}{f}" gradientUnits="userSpaceOnUse" {axis}>{stops}</linearGradient>{axis_anim}'
        )
    copies = _element("path", f'id="p{f}" {d} fill="url(#a{f})"', d_anim) + _element(
        "path", f'id="q{f}" {d} fill="url(#b{f})"', d_anim
    )
    out.append(f"<defs>{copies}</defs>")
    out.append(CHAPTER_FILTER.format(f=f, gain=svg_number(CHAPTER_ALPHA_GAIN, 4)))
    out.append(_element("path", f'{d} fill="url(#c{f})" filter="url(#x{f})"{vis[0]}', d_anim + vis[1]))
    return "".join(out)


def _visibility(seen: np.ndarray, dur: str) -> tuple[str, str]:
    """(initial display attribute, discrete <animate> of the changes or '') for one triangle's (T,) bits.

    display, not visibility: static renderers that ignore SMIL (Inkscape) draw visibility:hidden anyway."""
    t = len(seen)
    initial = "" if seen[0] else ' display="none"'
    changes = np.concatenate([[0], np.flatnonzero(seen[1:] != seen[:-1]) + 1])
    if len(changes) == 1:
        return initial, ""
    values = ";".join("inline" if seen[k] else "none" for k in changes.tolist())
    return initial, (
        f'<animate attributeName="display" calcMode="discrete" dur="{dur}" repeatCount="indefinite" '
        f'keyTimes="{_key_times(changes, t, floor=True)}" values="{values}"/>'
    )


def _stroke_width(off: np.ndarray, seen: np.ndarray, dur: str) -> tuple[str, str]:
    """(initial stroke-width attribute, discrete <animate> of its changes or '') for one triangle's (T,) frames
    whose stroke is off (seams.stroke_off); frames where it is hidden keep the last shown frame's width."""
    t = len(off)
    shown = np.flatnonzero(seen)
    if not off[shown].any():
        return "", ""
    last = np.maximum.accumulate(np.where(seen, np.arange(t), -1))
    state = off[np.where(last >= 0, last, shown[0])]
    initial = ' stroke-width="0"' if state[0] else ""
    changes = np.concatenate([[0], np.flatnonzero(state[1:] != state[:-1]) + 1])
    if len(changes) == 1:
        return initial, ""
    values = ";".join("0" if state[k] else svg_number(SEAM_STROKE, 2) for k in changes.tolist())
    return initial, (
        f'<animate attributeName="stroke-width" calcMode="discrete" dur="{dur}" repeatCount="indefinite" '
        f'keyTimes="{_key_times(changes, t, floor=True)}" values="{values}"/>'
    )


def write(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """Gouraud-shaded SVG: a still of options.frame, else the animation with gradients moving with the mesh;
    progress(stage, fraction of the writing done) between its steps and every GOURAUD_PROGRESS triangles."""
    method = "chapter" if options.shading == "gouraud-chapter" else "exact"
    t_all = sheet.n_frames
    still = options.frame is not None
    if still and not (0 <= options.frame < t_all):
        raise InputError(f"frame {options.frame} is outside 0..{t_all - 1}; choose --frame inside the range.")
    w, h = sheet.camera.width, sheet.camera.height
    dur = f"{svg_number(sheet.duration, 6)}s"
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
        corners = welded_ids(sheet.xy[frames], sheet.depth[frames])[tris]
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
    if method == "exact":
        signals, residual = _signals_exact(tri_xy, tri_rgb, color_scale, span(progress, 0.05, 0.5))
        report.figures["gouraud_rank1_max_residual"] = float(residual[active].max()) if active.any() else 0.0
        draw = _exact_triangle
    else:
        signals = _signals_chapter(tri_xy, tri_rgb, color_scale)
        draw = _chapter_triangle
    x = signals.matrix()
    progress("keys", 0.55)  # the signals (gradients of every triangle and frame) take about as long as the rest
    keys: dict[bool, tuple[np.ndarray, np.ndarray]] | None = None
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
        keys[True] = _hold_colours_in_range(*keys[True], active, signals)
        report.counts["gouraud_keys"] = int(sum(m.sum() for m, _ in keys.values()))
    emit = _Emit(signals, x, keys, t_all, dur)
    seam = f'<g stroke-width="{SEAM_STROKE}" stroke-linejoin="round" stroke-linecap="round">'
    group = seam if method == "exact" else "<g>"
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">',
        svg_anim.metadata(sheet, options, report, extra={"shading": options.shading, "gouraud_method": method},
                          order=order),
        f"<title>{escape(sheet.name)}</title>",
        group,
    ]
    if still and method == "exact" and UNDERLAY:
        out += underlay(sheet.xy[k][sheet.faces[order]], sheet.vertex_rgb[k][sheet.faces[order]],
                        sheet.part_ids[order], silhouette)
    progress("text", 0.65)
    for j, f in enumerate(order.tolist()):
        if j % GOURAUD_PROGRESS == 0:
            progress("text", 0.65 + 0.35 * j / len(order))
        if not emit.select(j, bool(closed[j])):
            continue
        vis = ("", "") if still else _visibility(sheet.visible[:, f], dur)
        stroke: bool | tuple[str, str] = bool(stroked[j])
        if stroke and stroke_off is not None:
            stroke = _stroke_width(stroke_off[:, j], sheet.visible[:, f], dur)
        out.append(draw(emit, f, vis, stroke))
    out.append("</g></svg>\n")
    report.counts["gouraud_triangles"] = len(order)
    return "\n".join(out).encode("utf-8")
