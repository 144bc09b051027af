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

from converter.encode import gouraudplan
from converter.encode.gouraudplan import SEAM_STROKE
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, Report, no_progress
from converter.sheet import Sheet
from converter.writers import svg_anim
from converter.writers.svgtext import key_times
from converter.writers.svgtext import number as svg_number

PATH_FMT = "M%.2f,%.2fL%.2f,%.2fL%.2f,%.2f"  # open: "Z" is added where every edge is stroked
COORD_FMT = "%.2f"
UNDERLAY_FMT = "M%.1f,%.1fL%.1f,%.1fL%.1f,%.1fZ"
COLOR_FMT = "#%06x"
GOURAUD_PROGRESS = 1024  # triangles written between progress reports
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


def _spelling(key: str) -> tuple[str, str]:
    """The attribute name and number format of a plan's signal track (gouraudplan.Signals keys)."""
    if key == "d":
        return "d", PATH_FMT
    if key == "bg":
        return "fill", COLOR_FMT
    if key.startswith("c"):
        return "stop-color", COLOR_FMT
    return key[:2], COORD_FMT


class _Track:
    """One attribute of one element: a printf format over columns of the per-triangle signal matrix."""

    def __init__(self, key: str, track: gouraudplan.Track) -> None:
        self.name, self.fmt = _spelling(key)
        self.cols, self.scale, self.color = track.cols, track.scale, track.color

    def texts(self, values: np.ndarray, suffix: str = "") -> list[str]:
        """Attribute text of each row of signal values (n, D), each followed by suffix."""
        v = values[:, self.cols] / self.scale
        if self.color:
            q = np.clip(np.round(v), 0, 255).astype(np.int64)
            return [COLOR_FMT % c for c in ((q[:, 0] << 16) | (q[:, 1] << 8) | q[:, 2]).tolist()]
        return [self.fmt % tuple(r) + suffix for r in v.tolist()]


class _Emit:
    """Per-triangle attribute text: a still (one row of values) or SMIL animations through the triangle's keys.

    Animated tracks come in groups (geometry, colour), each with its own keys: (mask (T+1, K), values (T+1, K, D)).
    """

    def __init__(self, signals: gouraudplan.Signals, values: np.ndarray,
                 keys: dict[bool, tuple[np.ndarray, np.ndarray]] | None, n_frames: int, dur: str) -> None:
        self.tracks = {k: _Track(k, tr) for k, tr in signals.tracks.items()}
        self.values, self.keys, self.t, self.dur = values, keys, n_frames, dur
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


def underlay(parts: list[tuple[np.ndarray, np.ndarray]]) -> list[str]:
    """The plan's per-part underlay (gouraudplan.underlay) as one path per part in its colour."""
    out = []
    for xy, rgb in parts:
        d = "".join(UNDERLAY_FMT % tuple(t) for t in xy.reshape(-1, 6).tolist())
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
    t_all = sheet.n_frames
    still = options.frame is not None
    if still and not (0 <= options.frame < t_all):
        raise InputError(f"frame {options.frame} is outside 0..{t_all - 1}; choose --frame inside the range.")
    w, h = sheet.camera.width, sheet.camera.height
    dur = f"{svg_number(sheet.duration, 6)}s"
    gp = gouraudplan.plan(sheet, options, progress)
    method, order, closed, stroked, stroke_off, keys = (gp.method, gp.order, gp.closed, gp.stroked, gp.stroke_off,
                                                        gp.keys)
    if gp.residual_max is not None:
        report.figures["gouraud_rank1_max_residual"] = gp.residual_max
    draw = _exact_triangle if method == "exact" else _chapter_triangle
    if gp.n_keys is not None:
        report.counts["gouraud_keys"] = gp.n_keys
    emit = _Emit(gp.signals, gp.values, keys, t_all, dur)
    seam = f'<g stroke-width="{SEAM_STROKE}" stroke-linejoin="round" stroke-linecap="round">'
    group = seam if method == "exact" else "<g>"
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">',
        svg_anim.metadata(sheet, options, report, extra={"shading": options.shading, "gouraud_method": method},
                          order=order),
        f"<title>{escape(sheet.name)}</title>",
        group,
    ]
    out += underlay(gp.underlay)
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
