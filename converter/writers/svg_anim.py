"""Animated flat-shaded SVG: one <path> per drawn triangle, back to front, SMIL-animated.

Three encodings of the same document structure:

- ``raw`` (options.raw): the chapter's unoptimised file, every frame's coordinates with 2 decimals, fill,
  stroke and display (the chapter's visibility) as discrete animations where they change.
- ``chapter``: the chapter's post-optimisations of the raw file: no coordinates while a triangle is hidden and
  runs where a visible triangle does not move merged, placed with keyTimes (exact to 2 decimals); a path keeps
  every frame where keyTimes would cost more (the chapter's own remark on long dynamic sequences).
- ``bounded`` (default): per path only the keys needed so SMIL's linear interpolation stays within
  options.tolerance px of the exact projection at every frame where the triangle is visible
  (converter.encode.freeknots: greedy keys with free values and keyTimes, or evenly spaced keys without them
  where that is shorter); integer coordinates in a viewBox scaled so rounding is part of the same budget;
  relative path syntax; static triangles without <animate>; fill and stroke are currentColor, a shared CSS
  class per colour; a triangle whose shade stays within options.color_tolerance levels of one colour is that
  static colour, others a discrete animation of held colours within it (``color_steps``; the default, 3
  levels, is the exact shading; 255, the mobile preset's, keeps every colour static: a colour animation costs
  players far more than a d animation, and an interpolated one about three times a discrete one,
  bench_playback); hidden frames folded into the d animation
  (converter.encode.collapse: the triangle collapses to a point within the half frame before it hides), so a
  path has at most a d and a color <animate>; never-visible triangles dropped.

Frame k shows at t = k / fps; dur = T / fps; linear animations end with a key at keyTime 1 (the loop end).
Every static attribute (group transform, d, colour class, display) holds frame 0 as played, so a renderer
that ignores SMIL (resvg, CairoSVG, rsvg-convert, Inkscape, thumbnailers) draws frame 0.
"""

from __future__ import annotations

import json
import math
from xml.sax.saxutils import escape

import numpy as np

from converter import heap, playcost
from converter.arrays import lengths, lexsort_ints
from converter.encode import collapse, flatplan, groups
from converter.encode import keys as keyframes
from converter.encode import palette as shared_colours
from converter.encode.budget import ErrorBudget
from converter.encode.flatplan import STROKE_PX, Strokes
from converter.encode.tracks import Tracks, blocks
from converter.options import ConversionOptions, Progress, Report, no_progress, span
from converter.sheet import Sheet
from converter.writers import svgtext
from converter.writers.metadata import source_fields
from converter.writers.svg_transforms import CLOSE, group_open
from converter.writers.svgtext import digits, key_times
from converter.writers.svgtext import number as svg_number

FORMAT_VERSION = 2
BYTES_PER_KEY = 24  # typical text of one path key ("M12 -34l5 6 -7 8z;" plus its keyTime): what groups weigh
UNIFORM_ROUNDS = (1.0, 1.5, 2.2)  # evenly spaced keys tried at these multiples of the greedy key count
UNIFORM_VALUES = 1 << 23  # float64 track values fitted at once (64 MB: 4,000 frames x 349 paths)
KEY_TEXT_KEYS = 1 << 15  # keys whose d and keyTimes texts exist at once (a block of paths)
RAW_COUNT_CELLS = 1 << 17  # vertex-frames per block when counting the raw encoding's bytes (~10 MB of temporaries)
RAW_WRITE_PATHS = 128  # paths per block when writing it (its one format call holds 18 objects per tri-frame)
HEX_DIGITS = np.frombuffer(b"0123456789abcdef", np.uint8)
ORDER_DONE = 0.02  # progress of the writing when the drawing order is known and the keys start
KEYS_DONE = 0.78  # progress of the writing when the keys are done and the text starts (wall time: the text took
# 20-22 % of the writer on the capture-like face, 8k x 1,000 and the ICT head x 1,000)


def _hex(levels: np.ndarray) -> np.ndarray:
    """'#rrggbb' (str array of levels' shape without its last axis) of 0-255 levels (..., 3): each hex digit
    looked up, its bytes viewed as one string (numpy's string functions took 1.8 s a million colour keys, this
    0.26 s)."""
    levels = np.asarray(levels, np.int64)
    code = (levels[..., 0] << 16) | (levels[..., 1] << 8) | levels[..., 2]
    text = np.empty(code.shape + (7,), np.uint8)
    text[..., 0] = ord("#")
    for i in range(6):
        text[..., 1 + i] = HEX_DIGITS[(code >> (20 - 4 * i)) & 15]
    return text.view("S7")[..., 0].astype("U7")


def key_time_decimals(n_frames: int, slope: np.ndarray, budget: float) -> np.ndarray:
    """Per key the fewest keyTimes decimals whose rounding moves the played value at most budget.

    Rounding a key time moves it by at most half a unit of the last decimal, T 10^-d / 2 frames; a linear
    interpolant moves by at most that times the slope (change per frame) of the segments the key bounds.
    Never fewer decimals than keep the times of distinct frames distinct."""
    need = n_frames * 0.5 * np.asarray(slope, np.float64) / budget
    d = np.ceil(np.log10(np.maximum(need, 1.0)))
    low = math.ceil(math.log10(max(n_frames, 2)))
    return np.clip(d, low, 12).astype(np.int64)


def metadata(sheet: Sheet, options: ConversionOptions, report: Report, extra: dict | None = None,
             order: np.ndarray | None = None) -> str:
    """The <metadata id="facesvg"> element: JSON with everything needed to re-project and check the output."""
    doc = {
        "format": "facesvg",
        "version": FORMAT_VERSION,
        **source_fields(sheet, options),
        "triangle_order": [int(i) for i in (sheet.order if order is None else order)],
    }
    if extra:
        doc.update(extra)
    return f'<metadata id="facesvg">{escape(json.dumps(doc, sort_keys=True, separators=(",", ":")))}</metadata>'


def write(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The animated SVG (raw when options.raw, else error-bounded), or the still of options.frame."""
    if options.frame is not None:
        return write_still(sheet, options, report, options.frame)
    return encode(sheet, options, report, "raw" if options.raw else "bounded", progress)


def path_ids(tris: np.ndarray) -> list[str]:
    """Unique element ids: f<triangle>, and f<triangle>b for a triangle's layer copy."""
    seen: set[int] = set()
    out = []
    for t in tris.tolist():
        out.append(f"f{t}b" if t in seen else f"f{t}")
        seen.add(t)
    return out


def _header(sheet: Sheet, scale: int) -> str:
    w, h = sheet.camera.width, sheet.camera.height
    return f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w * scale} {h * scale}" width="{w}" height="{h}">'


def _style(palette: np.ndarray, scale: int, bare: bool = False) -> str:
    """The stylesheet: fill and seam stroke in currentColor, a class per colour, and with bare the class 'n' of
    unstroked paths (seams.py)."""
    rules = "".join(f".c{i}{{color:{c}}}" for i, c in enumerate(_hex(palette).tolist()))
    sw = svg_number(STROKE_PX * scale, 3)
    return (f"<style>path{{fill:currentColor;stroke:currentColor;stroke-width:{sw};stroke-linejoin:round;"
            f"stroke-linecap:round}}{rules}{'.n{stroke:none}' if bare else ''}</style>")


def write_still(sheet: Sheet, options: ConversionOptions, report: Report, frame: int) -> bytes:
    """One frame as static paths (flatplan.still: exact colours, coordinates rounded to the tolerance's grid)."""
    fs = flatplan.still(sheet, options, frame)
    scale, tris, bare = fs.scale, fs.tris, fs.bare
    palette, cls = np.unique(fs.levels, axis=0, return_inverse=True)
    d = _path_strings(fs.corners, closed=fs.closed)
    out = [_header(sheet, scale), metadata(sheet, options, report, {"encoding": {"mode": "still", "scale": scale,
                                                                           "frame": frame}}, order=tris),
           f"<title>{escape(sheet.name)}</title>", _style(palette, scale, bool(bare.any())), "<g>"]
    out += [f'<path id="f{t}" class="c{c}{" n" if b else ""}" d="{s}"/>'
            for t, c, b, s in zip(tris.tolist(), cls.reshape(-1).tolist(), bare.tolist(), d)]
    out.append("</g></svg>\n")
    return "\n".join(out).encode("utf-8")


def _path_strings(q: np.ndarray, offset: np.ndarray | None = None, closed: np.ndarray | None = None) -> list[str]:
    """Shortest relative syntax 'm x y dx dy dx dy z' for integer triangles (N, 6), less offset (N, 2); without
    the 'z' where not closed (N,) (an open path: its stroke leaves out the closing edge).

    A leading 'm' is absolute and the pairs after it are implicit relative linetos, so no 'l' is needed."""
    r = q.copy()
    r[:, 2:4] = q[:, 2:4] - q[:, 0:2]
    r[:, 4:6] = q[:, 4:6] - q[:, 2:4]
    if offset is not None:
        r[:, 0:2] -= offset
    return svgtext.subpaths(r, closed)


def offsets(rows: np.ndarray, pk: np.ndarray, p: int) -> np.ndarray:
    """Per path (P, 2) a static integer translate for its keys' moveto (rows (K, 6), path of each pk), where the
    digits it saves outweigh its transform attribute; zero elsewhere."""
    out = np.zeros((p, 2), np.int64)
    if not len(rows):
        return out
    counts = np.bincount(pk, minlength=p)
    starts = np.cumsum(counts) - counts
    has = counts > 0
    mid = (starts + counts // 2)[has]
    for c in (0, 1):  # the median moveto of each path's keys
        out[has, c] = rows[lexsort_ints((rows[:, c], pk)), c][mid]
    m = rows[:, :2]
    saved = np.bincount(pk, (digits(m) - digits(m - out[pk])).sum(axis=1), minlength=p)
    cost = len(' transform="translate( )"') + digits(out).sum(axis=1)
    out[saved <= cost] = 0
    return out


def _raw_strings(tri_xy: np.ndarray, closed: bool = True) -> list[str]:
    """The chapter's 'M x,y L x,y L x,y Z' with 2 decimals, (N, 6) px -> N strings (one format call); without
    the 'Z' when not closed."""
    c = np.rint(np.asarray(tri_xy, np.float64) * 100).astype(np.int64)
    if not len(c):
        return []
    a = np.abs(c)
    fields = np.empty(c.shape + (3,), object)
    fields[..., 0] = np.where(c < 0, "-", "")
    fields[..., 1] = a // 100
    fields[..., 2] = a % 100
    one = "M%s%d.%02d,%s%d.%02dL%s%d.%02d,%s%d.%02dL%s%d.%02d,%s%d.%02d" + ("Z\x00" if closed else "\x00")
    return ((one * len(c)) % tuple(fields.ravel().tolist()))[:-1].split("\x00")


def _raw_texts(tri_xy: np.ndarray, closed: np.ndarray) -> list[str]:
    """_raw_strings of each row (N, 6), closed (N,) or open."""
    out = np.empty(len(tri_xy), object)
    for shut in (True, False):
        sel = np.flatnonzero(closed == shut)
        if len(sel):
            out[sel] = np.asarray(_raw_strings(tri_xy[sel], shut), object)
    return out.tolist()


def _discrete(attribute: str, codes: np.ndarray, names: list[str], kt: list[str], dur: str) -> list[str]:
    """Per path a discrete <animate> of codes (T, P) at their change points ('' when constant)."""
    t, p = codes.shape
    change = np.zeros((t, p), bool)
    change[1:] = codes[1:] != codes[:-1]
    moving = change.any(axis=0)
    out = [""] * p
    cols, rows = np.nonzero(change.T)  # sorted by path, then frame
    bounds = np.searchsorted(cols, np.arange(p + 1))
    for j in np.flatnonzero(moving).tolist():
        frames = [0] + rows[bounds[j]:bounds[j + 1]].tolist()
        out[j] = (f'<animate attributeName="{attribute}" calcMode="discrete" dur="{dur}" repeatCount="indefinite" '
                  f'keyTimes="{";".join(kt[k] for k in frames)}" '
                  f'values="{";".join(names[codes[k, j]] for k in frames)}"/>')
    return out


def encode(sheet: Sheet, options: ConversionOptions, report: Report, mode: str = "bounded",
           progress: Progress = no_progress) -> bytes:
    """The animated SVG in one of the encodings: 'raw', 'chapter' or 'bounded' (module docstring); progress(stage,
    fraction of the writing done) as it goes (the plan's keys up to KEYS_DONE, then the text)."""
    t = sheet.n_frames
    progress("order", 0.0)
    dur = f"{sheet.duration:.6f}".rstrip("0").rstrip(".") + "s"  # SMIL clock values need the leading digit
    extra: dict = {"encoding": {"mode": mode}}
    costs = groups.Costs(lambda m: len(group_open(m, t, dur)), len(CLOSE), BYTES_PER_KEY)
    fp = flatplan.plan(sheet, options, mode, costs, span(progress, ORDER_DONE, KEYS_DONE))
    if mode == "bounded":  # the raw file's d values alone, counted exactly (writing them would cost more)
        report.sizes["raw_d_values"] = raw_values_bytes(sheet.xy, sheet.faces[fp.tris])
    p = fp.n_paths
    if mode in ("raw", "chapter"):
        body = _encode_raw(sheet, fp.tris, fp.active, fp.track, dur, chapter=mode == "chapter", strokes=fp.strokes,
                           progress=span(progress, ORDER_DONE, 1.0))
        scale = 1
    else:
        body, scale, enc = _encode_keyed(sheet, fp, dur, report, options.color_tolerance,
                                         span(progress, KEYS_DONE, 1.0, "text"))
        extra["encoding"].update(enc)
    tris = fp.tris
    head = [_header(sheet, scale), metadata(sheet, options, report, extra, order=tris),
            f"<title>{escape(sheet.name)}</title>"]
    report.counts["paths"] = p if fp.joined is None else len(fp.joined.starts) - 1
    if mode == "bounded":
        report.figures["playback_ms_4x"] = playcost.predict_ms(report.counts)
    report.counts["depth_conflicts"] = fp.conflicts
    report.counts["depth_conflicts_left"] = fp.residual
    report.counts["layer_copies"] = int(len(tris) - len(np.unique(tris)))
    if mode in ("raw", "chapter"):  # already bytes, a block of paths each: joined once, never as one str
        return b"\n".join(["\n".join(head).encode("utf-8"), *body, b"</g></svg>\n"])
    text = "\n".join([*head, *body, "</g></svg>\n"])
    del body  # the document's text alone, then its bytes
    return text.encode("utf-8")


def _shared_colours(shared: shared_colours.Palette, t: int, dur: str, decimals: int) -> tuple[str, str, dict[int, str]]:
    """The animated entries of a shared palette that paths use: the <defs> (a one-stop userSpaceOnUse gradient per
    entry whose stop colour animates, discrete; bench_palette_refs measured the references), the CSS rules (a class
    per entry painting fill and stroke with it) and each entry's class name, numbered by first use."""
    live = np.flatnonzero(shared.animated())
    used = np.zeros(shared.size, bool)
    used[shared.entry[shared.entry >= 0]] = True
    live = live[used[live]]
    names = {int(k): f"p{i}" for i, k in enumerate(live.tolist())}
    epk, efk = np.nonzero(shared.mask[:, live].T)
    hexes = _hex(shared.values[:, live].transpose(1, 0, 2)[epk, efk]).tolist()
    bounds = np.searchsorted(epk, np.arange(len(live) + 1)).tolist()
    kt = key_times(efk, t, decimals, "early")
    defs, rules = [], []
    for i in range(len(live)):
        a, b = bounds[i], bounds[i + 1]
        defs.append(f'<linearGradient id="p{i}" gradientUnits="userSpaceOnUse"><stop stop-color="{hexes[a]}">'
                    f'<animate attributeName="stop-color" calcMode="discrete" dur="{dur}" '
                    f'repeatCount="indefinite" keyTimes="{";".join(kt[a:b])}" values="{";".join(hexes[a:b])}"/>'
                    "</stop></linearGradient>")
        rules.append(f".p{i}{{fill:url(#p{i});stroke:url(#p{i})}}")
    return "<defs>" + "".join(defs) + "</defs>", "".join(rules), names


def _merged_geometry(bands: list[flatplan.MergedBand], sets: list[tuple[int, int]], gain: np.ndarray,
                     budget: ErrorBudget, t: int, dur: str, closed: np.ndarray) -> tuple[list[str], list[str], int]:
    """Per merged set (first, one-past-last path) its <animate> of d and frame-0 d from its joint keys
    (flatplan.merged_keys) over t frames: one subpath per path; gain (P,): error gain of each path's group; closed
    (P,): a path's subpath ends with 'z' (else it is open)."""
    anims, firsts, n_keys = [""] * len(sets), [""] * len(sets), 0
    for band in bands:
        a_, f_, n = _merged_band(band, [sets[k] for k in band.sets.tolist()], gain, budget, t, dur, closed)
        for k, a, f in zip(band.sets.tolist(), a_, f_):
            anims[k], firsts[k] = a, f
        n_keys += n
    return anims, firsts, n_keys


def _merged_band(band: flatplan.MergedBand, sets: list[tuple[int, int]], gain: np.ndarray, budget: ErrorBudget,
                 t: int, dur: str, closed: np.ndarray) -> tuple[list[str], list[str], int]:
    """_merged_geometry of one band's sets: their animations, frame-0 d texts and keys written."""
    whole, q = band.timeline, len(sets)
    scale = budget.scale
    width = band.width
    idx = np.array([[min(a + i, b - 1) for i in range(width)] for a, b in sets], np.int64)  # (Q, M) padded
    rows = np.rint(whole.values * scale).astype(np.int64)
    kt_text, _ = timeline_key_times(whole, rows, t, gain[idx].max(axis=1)[whole.path] / scale, budget.keytimes)
    kb = np.searchsorted(whole.path, np.arange(q + 1))
    anims, firsts = [], []
    for k, (a, b) in enumerate(sets):
        n = b - a
        r = rows[kb[k]:kb[k + 1], :n * 6].reshape(-1, 6)
        shut = closed[a:b]
        off = np.zeros((len(r), 2), np.int64)
        # a moveto after z is relative to the start of the subpath before, after an open one to its last point
        before = np.where(shut[:-1, None], r.reshape(-1, n, 6)[:, :-1, :2], r.reshape(-1, n, 6)[:, :-1, 4:6])
        off.reshape(-1, n, 2)[:, 1:] = before
        parts = _path_strings(r, off, np.tile(shut, len(r) // n))
        text = ["".join(parts[i:i + n]) for i in range(0, len(parts), n)]
        firsts.append(text[0])
        moving = len(set(text)) > 1
        anims.append(f'<animate attributeName="d" dur="{dur}" repeatCount="indefinite" '
                     f'keyTimes="{";".join(kt_text[kb[k]:kb[k + 1]])}" values="{";".join(text)}"/>' if moving else "")
    return anims, firsts, len(rows)


def raw_values_bytes(xy: np.ndarray, corners: np.ndarray) -> int:
    """Exact bytes of the raw encoding's d values for the triangles of vertex ids corners (P, 3) over xy
    (T, V, 2) px: every frame plus the held last, 'M x,y L x,y L x,y Z' with 2 decimals, ';' between (the bulk
    of a raw file; counted, not written). A vertex's text is the same in every path that has it, so each used
    vertex is counted once per frame and weighted by its uses, a block of vertices at a time."""
    t, p = xy.shape[0], len(corners)
    if not p or not t:
        return 0
    uses = np.bincount(np.asarray(corners).ravel(), minlength=xy.shape[1])
    verts = np.flatnonzero(uses)
    total = 0
    block = max(1, RAW_COUNT_CELLS // t)
    for a in range(0, len(verts), block):
        v = verts[a:a + block]
        c = np.rint(np.asarray(np.take(xy, v, axis=1), np.float64) * 100).astype(np.int64)
        per = (digits(np.abs(c) // 100) + 3 + (c < 0)).sum(axis=2)  # (T, n): "x.xx" "y.yy" of each vertex
        total += int(((per.sum(axis=0) + per[-1]) * uses[v]).sum())
    return total + (t + 1) * p * (7 + 1) - p  # M L L Z and two commas per value, ';' between values


def _encode_raw(sheet: Sheet, tris: np.ndarray, active: np.ndarray, track: Tracks, dur: str,
                chapter: bool = False, strokes: Strokes | None = None, progress: Progress = no_progress) -> list[bytes]:
    """The raw file: every frame's coordinates (2 decimals) as evenly spaced values (frame k at k/T, the last
    held to T); fill, stroke and display as discrete animations where they change. With chapter=True the
    chapter's post-optimisations: coordinates only at frames that need them (nothing while hidden, a still
    run reduced to its two ends) placed with keyTimes, exact to 2 decimals. Seam strokes as strokes says (open
    paths without 'Z', unstroked ones without stroke; default: every edge stroked). Written RAW_WRITE_PATHS paths
    at a time, each block's lines joined into bytes at once, so the texts of every frame of every path never
    exist at once as strings (memory follows the output)."""
    t, p = active.shape
    kt = key_times(np.arange(t + 1), t, 6, "early")
    kt_lin = key_times(np.arange(t + 1), t, 6) if chapter else []
    out = [f'<g stroke-width="{svg_number(STROKE_PX, 3)}" stroke-linejoin="round" stroke-linecap="round">'.encode()]
    ids = path_ids(tris)
    columns = sheet.color_columns(tris)
    for a in range(0, p, RAW_WRITE_PATHS):
        progress("text", a / p)
        sl = slice(a, a + RAW_WRITE_PATHS)
        closed = strokes.closed(tris[sl]) if strokes is not None else np.ones(len(tris[sl]), bool)
        bare = strokes.bare(tris[sl]) if strokes is not None else np.zeros(len(tris[sl]), bool)
        lines = _raw_block(np.take(sheet.face_rgb, columns[sl], axis=1), active[:, sl], track.take(sl), ids[sl], kt,
                           kt_lin, dur, chapter, closed, bare)
        out.append("\n".join(lines).encode("utf-8"))
    return out


def _raw_block(rgb: np.ndarray, active: np.ndarray, track: np.ndarray, ids: list[str], kt: list[str],
               kt_lin: list[str], dur: str, chapter: bool, closed: np.ndarray, bare: np.ndarray) -> list[str]:
    """_encode_raw's paths for one block: colours rgb (T, P, 3), active (T, P), tracks (T, P, 6) px; closed and
    bare (P,): the d ends with 'Z', the path has no stroke."""
    t, p = active.shape
    track = np.asarray(track, np.float64)
    levels = np.clip(np.round(np.asarray(rgb) * 255), 0, 255).astype(np.int64)
    code = (levels[..., 0] << 16) | (levels[..., 1] << 8) | levels[..., 2]  # (T, P)
    packed, fill_codes = np.unique(code, return_inverse=True)
    names = _hex(np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255], axis=1)).tolist()
    fill_codes = fill_codes.reshape(t, p)
    vis = _discrete("display", active.astype(np.int64), ["none", "inline"], kt, dur)
    fills = _discrete("fill", fill_codes, names, kt, dur)
    strokes = [a.replace('"fill"', '"stroke"', 1) for a in fills]
    raw = _raw_texts(track.reshape(-1, 6), np.tile(closed, t))
    if chapter:
        keys = keyframes.reduce(np.rint(track * 100), active, 1e-6)  # exact in hundredths of a pixel
        pk, fk = np.nonzero(keys.mask.T)
        text = _raw_texts(keys.values.transpose(1, 0, 2)[pk, fk] / 100.0, closed[pk])
        bounds = np.searchsorted(pk, np.arange(p + 1)).tolist()
        moving = _varying(pk, p, keys.values.transpose(1, 0, 2)[pk, fk])
        fkl = fk.tolist()
    out = []
    for j in range(p):
        if chapter and (not moving[j] or (bounds[j + 1] - bounds[j]) * 1.4 < t + 1):
            # keyTimes pay when many frames are still or hidden; on a moving triangle every frame is cheaper.
            a, b = bounds[j], bounds[j + 1]
            first = text[a]
            anim = (f'<animate attributeName="d" dur="{dur}" repeatCount="indefinite" keyTimes="'
                    f'{";".join([kt_lin[k] for k in fkl[a:b]])}" values="{";".join(text[a:b])}"/>') if moving[j] else ""
        else:
            vals = raw[j::p]
            vals = vals + [vals[-1]]
            first = vals[int(np.argmax(active[:, j]))]
            anim = (f'<animate attributeName="d" dur="{dur}" repeatCount="indefinite" values="{";".join(vals)}"/>'
                    if t > 1 else "")
        colour = names[fill_codes[0, j]]
        attrs = f'id="{ids[j]}" d="{first}" fill="{colour}"' + ("" if bare[j] else f' stroke="{colour}"')
        if not active[0, j]:
            attrs += ' display="none"'  # not visibility: Inkscape draws visibility:hidden paths
        out.append(f"<path {attrs}>{anim}{vis[j]}{fills[j]}{'' if bare[j] else strokes[j]}</path>")
    return out


def _keyed(attribute: str, pk: np.ndarray, p: int, text: list[str], kt_text: list[str], dur: str,
           animate: np.ndarray, discrete: bool = False) -> tuple[list[str], list[str], int]:
    """Per path an <animate> through its keys, linear or (discrete) each value held until the next key (pk: the
    path of each key, sorted; value and keyTimes texts path-major) where animate[j]."""
    mode = 'calcMode="discrete" ' if discrete else ""
    bounds = np.searchsorted(pk, np.arange(p + 1)).tolist()
    out, first, n = [""] * p, [""] * p, 0
    for j in range(p):
        a, b = bounds[j], bounds[j + 1]
        if a == b:
            continue
        first[j] = text[a]
        if not animate[j]:
            n += 1
            continue
        out[j] = (f'<animate attributeName="{attribute}" {mode}dur="{dur}" repeatCount="indefinite" '
                  f'keyTimes="{";".join(kt_text[a:b])}" values="{";".join(text[a:b])}"/>')
        n += b - a
    return out, first, n


def _varying(pk: np.ndarray, p: int, rows: np.ndarray) -> np.ndarray:
    """Bool (P,): the key rows (path-major, (K, D); pk the path of each) of a path are not all equal."""
    bounds = np.searchsorted(pk, np.arange(p + 1))
    counts = np.diff(bounds)
    out = np.zeros(p, bool)
    has = counts > 0
    if not len(rows):
        return out
    firsts = rows[np.repeat(bounds[:-1][has], counts[has])]
    diff = (rows != firsts).any(axis=1)
    out[has] = np.logical_or.reduceat(diff, bounds[:-1][has])
    return out


def _uniform_instead(attribute: str, track: Tracks, active: np.ndarray, counts: np.ndarray,
                     keyed_len: np.ndarray, value_len: np.ndarray, scale: float, radius: float | np.ndarray,
                     pairs: bool, fmt, dur: str, anims: list[str]) -> dict[int, np.ndarray]:
    """Replace a path's keyed animation by evenly spaced keys (no keyTimes) where that is shorter.

    Evenly spaced values are least-squares fitted and checked exactly (rounding included) against the bound
    (Euclidean per 2D point when pairs, else per coordinate), so they often need no more keys than the greedy
    pass and save the keyTimes text. counts: greedy keys per path; keyed_len: its animation's length; value_len:
    the typical length of one value; fmt(values (K, D) ints, path index) -> K strings. anims is updated in place;
    returns the new values (K, D) of the paths changed (their first is the frame-0 value the static attribute
    must hold)."""
    t, p = active.shape
    ladder = np.unique(np.round(np.geomspace(2, t + 1, 48)).astype(np.int64))
    values: dict[int, np.ndarray] = {}
    todo = np.flatnonzero((counts >= 3) & (keyed_len > 0))
    for factor in UNIFORM_ROUNDS:
        want = np.ceil(counts[todo] * factor).astype(np.int64)
        cand = ladder[np.minimum(np.searchsorted(ladder, want), len(ladder) - 1)]
        head = len(f'<animate attributeName="{attribute}" dur="{dur}" repeatCount="indefinite" values=""/>')
        worth = head + cand * (value_len[todo] + 1) - 1 < keyed_len[todo]
        for n in np.unique(cand[worth]).tolist():
            # a block of paths at a time (each is fitted on its own): at once, the float64 tracks of every path
            # with this key count are 48 B per path and frame (GBs on a 4,000-frame capture)
            every = todo[worth & (cand == n)]
            for sl in blocks(len(every), max(1, UNIFORM_VALUES // max(t * track.shape[2], 1))):
                idx = every[sl]
                q, ok = keyframes.uniform_fit(np.asarray(track.take(idx), np.float64),
                                              np.take(active, idx, axis=1), n, scale,
                                              radius if np.isscalar(radius) else radius[idx], pairs)
                for j, col in zip(idx[ok].tolist(), np.flatnonzero(ok).tolist()):
                    values[j] = q[:, col]
        todo = np.setdiff1d(todo, np.fromiter(values, np.int64, len(values)))
    for j in sorted(values):
        anims[j] = (f'<animate attributeName="{attribute}" dur="{dur}" repeatCount="indefinite" '
                    f'values="{";".join(fmt(values[j], j))}"/>')
    return values


def timeline_key_times(tl: collapse.Timeline, rows: np.ndarray, t: int, px: float | np.ndarray,
                       budget: float) -> tuple[list[str], np.ndarray]:
    """keyTimes text of a collapse.Timeline's keys (rows: their integer values, px: px per unit) and the
    decimals of each: rounded within budget px on the segments a key bounds, in the direction its snap allows
    (then twice the distance), never across the half frame that separates it from a collapse."""
    pk, half = tl.path, tl.half
    k = len(pk)
    slope = np.zeros(k)
    bare = np.zeros(k)  # the same without the collapse segments
    if k > 1:
        same = pk[1:] == pk[:-1]
        dv = np.diff(rows.astype(np.float64), axis=0)
        step = lengths(dv.reshape(len(dv), -1, 2)).max(axis=1) * np.broadcast_to(px, (k,))[:-1]
        seg = np.where(same, step / np.maximum(np.diff(half), 1) * 2, 0.0)  # per frame
        plain = np.where(tl.collapsed[1:] | tl.collapsed[:-1], 0.0, seg)
        slope[:-1] = seg
        slope[1:] = np.maximum(slope[1:], seg)
        bare[:-1] = plain
        bare[1:] = np.maximum(bare[1:], plain)
    snap = tl.snap
    near_collapse = (snap != 0) | tl.collapsed
    use = np.where(snap == -2, slope, np.where(np.abs(snap) == 1, 2 * bare, bare))
    decimals = key_time_decimals(t, use, budget)
    if t > 1:  # a key next to a collapse keeps to its quarter of a frame
        decimals = np.where(near_collapse, np.maximum(decimals, math.ceil(math.log10(8 * t))), decimals)
    out = np.empty(k, object)
    for code, mode in ((-1, "floor"), (1, "ceil"), (0, "nearest"), (-2, "nearest")):
        sel = snap == code
        if sel.any():
            out[sel] = key_times(half[sel], 2 * t, decimals[sel], mode)
    return out.tolist(), decimals


def _d_animations(tl: collapse.Timeline, p: int, t: int, gain: np.ndarray | None, view_scale: int,
                  time_budget: float, dur: str, closed: np.ndarray) -> tuple[list[str], list[str], int, np.ndarray,
                                                                             np.ndarray, np.ndarray, np.ndarray,
                                                                             list[int]]:
    """The d <animate> of each of p paths from its keys tl (gain (P,): error gain of each path's group, None for
    none; closed (P,): the d ends with 'z'): animations, frame-0 d texts, keys written, moving (P,), static
    offsets (P, 2), keys (P,), mean key text length (P,) and the [least, most] keyTime decimals. A block of
    paths at a time (KEY_TEXT_KEYS keys), so that a string per key exists only for one block: on a long capture
    they would outweigh the output."""
    bounds = np.searchsorted(tl.path, np.arange(p + 1))
    counts = np.diff(bounds)
    anims: list[str] = []
    firsts: list[str] = []
    n_keys = 0
    moving, off, per_key = np.zeros(p, bool), np.zeros((p, 2), np.int64), np.zeros(p)
    lows, highs = [], []
    a = 0
    while a < p:  # whole paths, about KEY_TEXT_KEYS keys a block (at least one path)
        b = min(p, max(a + 1, int(np.searchsorted(bounds, bounds[a] + KEY_TEXT_KEYS, side="right")) - 1))
        ks = slice(bounds[a], bounds[b])
        pk = tl.path[ks] - a
        sub = collapse.Timeline(pk, tl.half[ks], tl.values[ks], tl.collapsed[ks], tl.snap[ks])
        rows = np.rint(np.multiply(sub.values, view_scale, dtype=np.float64)).astype(np.int64)
        px = (gain[a:b][pk] if gain is not None else 1.0) / view_scale  # local units -> output px
        kt_text, decimals = timeline_key_times(sub, rows, t, px, time_budget)
        if len(decimals):
            lows.append(int(decimals.min()))
            highs.append(int(decimals.max()))
        moving[a:b] = _varying(pk, b - a, rows)
        o = offsets(rows, pk, b - a)
        o[~moving[a:b]] = 0
        off[a:b] = o
        text = _path_strings(rows, o[pk], closed[a:b][pk])
        block_anims, block_firsts, n = _keyed("d", pk, b - a, text, kt_text, dur, moving[a:b])
        anims += block_anims
        firsts += block_firsts
        n_keys += n
        per_key[a:b] = np.bincount(pk, np.fromiter(map(len, text), np.float64, len(text)), b - a)
        a = b
    per_key /= np.maximum(counts, 1)
    return anims, firsts, n_keys, moving, off, counts, per_key, [min(lows), max(highs)] if lows else []


def _encode_keyed(sheet: Sheet, fp: flatplan.FlatPlan, dur: str, report: Report, color_tolerance: float,
                  progress: Progress = no_progress) -> tuple[list[str], int, dict]:
    """The error-bounded integer encoding (module docstring) of a bounded plan: its paths' keys, rigid groups,
    merged elements and colours (the shared palette's entries, else each path's own held steps within
    color_tolerance levels). Takes the plan's track and timeline (set to None here, so that each is freed as soon
    as it is used: on a long capture they are the largest arrays)."""
    track, tl = fp.track, fp.timeline
    fp.track = fp.timeline = None
    budget, tris, active, st, plan = fp.budget, fp.tris, fp.active, fp.strokes, fp.rigid
    joined, shared = fp.joined, fp.shared
    t, p = active.shape
    tol = budget.tolerance
    view_scale = budget.scale
    time_budget = budget.keytimes
    radius, bound = fp.radius()
    progress("text", 0.0)
    closed = st.closed(tris)
    geo = _d_animations(tl, p, t, plan.gain if plan is not None else None, view_scale, time_budget, dur, closed)
    progress("text", 0.2)
    del tl
    heap.give_back()  # the key texts' blocks
    d_anims, d_first, n_keys, moving, off, key_counts, per_key, decimals = geo
    color_tol = color_tolerance
    enc = {"scale": view_scale, "tolerance": tol, "fit_px": round(float(np.min(radius)), 6),
           "color_levels": color_tol, "hidden": "collapsed", "keytime_decimals": decimals}
    starts, sets = fp.starts, fp.sets
    inside = flatplan.merged_paths(sets)
    d_len = np.array([len(a) for a in d_anims])
    d_len[~active.all(axis=0)] = 0  # evenly spaced keys cannot collapse a hidden triangle
    d_len[inside] = 0  # a merged path's d is keyed for all its triangles together (_merged_geometry)
    d_uniform = _uniform_instead("d", track, active, key_counts, d_len, per_key, view_scale,
                                 bound, True, lambda v, j: _path_strings(v, np.broadcast_to(off[j], (len(v), 2)),
                                                                         np.broadcast_to(closed[j], len(v))),
                                 dur, d_anims)
    heap.give_back()  # the fits' temporaries
    progress("text", 0.65)
    for j in [j for j in d_uniform if active[0, j]]:  # the static d holds frame 0 as played where it is shown
        d_first[j] = _path_strings(d_uniform[j][:1], off[j:j + 1], closed[j:j + 1])[0]
    if sets:  # a merged path's d is keyed for all its triangles together
        m_anims, m_first, m_keys = _merged_geometry(fp.merged, sets, fp.gain(), budget, t, dur, closed)
    del track
    # Colour: held steps within the colour tolerance (color_steps); the first step's colour is the path's class.
    # A step shows from frame k: placed half a frame early, rounded by at most a quarter frame.
    c_dec = math.ceil(math.log10(2 * max(t, 1)))
    if shared is not None:  # every path refers to its palette entry: per path only its frame-0 colour and class
        c_vary = shared.animated()[shared.entry]
        c_anims = [""] * p
        n_color_keys = int(np.where(c_vary, shared.mask.sum(axis=0)[shared.entry], 1).sum())
        first = shared.values[0, shared.entry].astype(np.int64)  # frame 0 is every entry's first step
        base = (first[:, 0] << 16) | (first[:, 1] << 8) | first[:, 2]
        progress("text", 0.8)
    else:
        ckeys = fp.steps  # each path's own held steps (a merged path's one static colour)
        progress("text", 0.8)
        cpk, cfk = np.nonzero(ckeys.mask.T)
        crow = ckeys.values.transpose(1, 0, 2)[cpk, cfk].astype(np.int64)
        c_vary = _varying(cpk, p, crow)
        c_anims, _, n_color_keys = _keyed("color", cpk, p, _hex(crow).tolist(), key_times(cfk, t, c_dec, "early"),
                                          dur, c_vary, discrete=True)
        cbounds = np.searchsorted(cpk, np.arange(p + 1))[:-1]
        packed = (crow[:, 0] << 16) | (crow[:, 1] << 8) | crow[:, 2]
        base = packed[np.minimum(cbounds, max(len(packed) - 1, 0))] if len(packed) else np.zeros(p, np.int64)
    n_uniform = len(d_uniform)
    values, counts = np.unique(base, return_counts=True)
    rank = np.lexsort((values, -counts))  # the most used colour gets the shortest class name
    remap = np.empty(len(values), np.int64)
    remap[rank] = np.arange(len(values))
    cls = remap[np.searchsorted(values, base)]
    pal = values[rank]
    palette = np.stack([(pal >> 16) & 255, (pal >> 8) & 255, pal & 255], axis=1)
    bare = st.bare(tris)
    style = _style(palette, view_scale, bool(bare.any()))
    names = [f"c{c}" for c in cls.tolist()]
    defs = ""
    if shared is not None:  # each animated entry animates once; its paths refer to it
        defs, rules, entry_names = _shared_colours(shared, t, dur, c_dec)
        for j in np.flatnonzero(c_vary).tolist():
            names[j] = entry_names[shared.entry[j]]
        # before the unstroked class, which must win over an entry's stroke (equal specificity: the later rule)
        at = style.find(".n{stroke:none}")
        at = at if at >= 0 else style.rindex("</style>")
        style = style[:at] + rules + style[at:]
        report.counts["shared_color_animations"] = len(entry_names)
        report.counts["palette_entries"] = shared.size
    out = [style, *([defs] if defs else []), group_open(plan.head, t, dur) if plan is not None else "<g>"]
    ids = path_ids(tris)
    bare_cls = np.where(bare, " n", "").tolist()
    moves = [f' transform="translate({x} {y})"' if x or y else "" for x, y in off.tolist()]
    opens: dict[int, str] = {}
    closes: set[int] = set()
    if plan is not None:
        texts: dict[int, str] = {}  # one text per band, repeated for each of its runs
        for a, b in plan.groups.tolist():
            band = int(plan.band[a])
            if band not in texts:
                texts[band] = group_open(plan.motions[band], t, dur)
            opens[a] = texts[band]
            closes.add(b - 1)
    merged = {a: k for k, (a, _) in enumerate(sets)}
    kept = np.ones(p, bool)
    kept[inside] = False
    animated = sum(1 for a, k in zip(d_anims, kept.tolist()) if a and k) + (sum(map(bool, m_anims)) if sets else 0)
    report.counts["color_animations"] = sum(bool(c_anims[a]) for a in starts[:-1].tolist())  # counted now: the
    # loop hands each text over
    for a, b in zip(starts[:-1].tolist(), starts[1:].tolist()):
        if a in opens:
            out.append(opens[a])
        if a in merged:
            k = merged[a]
            body = m_anims[k] + (c_anims[a] if shared is not None else "")
            el = f'<path id="{ids[a]}" class="{names[a]}" d="{m_first[k]}"'
        else:
            body = d_anims[a] + c_anims[a]
            d_anims[a] = c_anims[a] = ""  # each text lives on only in the document's
            el = f'<path id="{ids[a]}" class="{names[a]}{bare_cls[a]}"{moves[a]} d="{d_first[a]}"'
        out.append(f"{el}>{body}</path>" if body else f"{el}/>")
        if b - 1 in closes:
            out.append(CLOSE)
    if sets:  # the merged paths' own keys replace their triangles' single ones in the counts
        inside_keys = int(np.where(moving[inside], key_counts[inside], 1).sum())  # as _keyed counted them
        n_keys += m_keys - inside_keys
        report.counts["merged_paths"] = len(sets)
        report.counts["merged_triangles"] = int(len(inside))
        report.counts["merge_palette"] = joined.colours
        report.counts["merge_size"] = joined.size
    report.counts["keys"] = n_keys
    report.counts["uniform_paths"] = n_uniform
    report.counts["color_keys"] = n_color_keys
    report.counts["static_paths"] = int((~moving).sum())
    report.counts["palette"] = len(palette)
    report.counts["animated_paths"] = animated
    err = fp.colour_error(sheet)
    report.figures["color_error_max_levels"] = float(err.max(initial=0.0))
    report.figures["color_error_p99_levels"] = float(np.percentile(err, 99, overwrite_input=True)) if err.size else 0.0
    report.figures["keys_per_path"] = n_keys / max(p, 1)
    if plan is not None:
        report.counts.update({f"rigid_{k}": int(v) for k, v in plan.stats.items() if k != "max_gain"})
        enc["rigid"] = {"groups": len(opens), "max_gain": round(plan.stats["max_gain"], 6)}
    return out, view_scale, enc
