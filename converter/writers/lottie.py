"""Lottie and dotLottie: the flat animation's plan (converter.encode.flatplan) spelt as Lottie JSON.

The same FlatPlan the animated SVG spells (svg_anim), for native players (lottie-ios, lottie-android, lottie-web,
ThorVG through dotLottie):

- one shape layer (ty 4) from frame 0 to T at the source's rate, its transform a static scale of 100 / scale %:
  coordinates are the plan's integers on the 1 / budget.scale px grid, as in the SVG's viewBox;
- the rigid plan's head as a group (gr) around everything and each run of a band's paths as a group inside it,
  their transforms (tr) keyed like the SVG's animateTransform stack ``translate rotate skewX scale``, which is
  Lottie's ``p r sk s`` with sk = -skewX, sa = 0, s = 100 x scale and no anchor: Lottie applies
  T(p) R(r) R(-sa) Kx(-sk) R(sa) S(s / 100) T(-a) to a point (checked by rendering: tests/reference); a
  transform key sits at its SMIL keyTime x T frames (keyTimes rounded as the played matrices are);
- one group per element (a path, or a merged set drawn as one element of subpaths): a ``sh`` per subpath
  (keyed at the plan's key times, half frames, linear; static when it never moves; open where its seam stroke
  leaves out the closing edge), a stroke ``st`` unless bare (the fill's colour, STROKE_PX wide, round caps and
  joins) and a fill ``fl``: the palette entry's held steps (hold keyframes, half a frame early, as the SVG places
  them) or the path's own; a hidden triangle is collapsed to a point, as in the SVG.

Lottie draws the first item of a list on top, so every list is the document order reversed (subpaths of one
element, which share one fill, stay in document order). Key texts are written directly, not through json.dumps:
a long capture has millions of them. Linear easing is ``o`` (0, 0) ``i`` (1, 1) on each key that starts a
segment; the last key of a property has none; tangents of the straight edges are zeros (lottie-web reads them).
The root's ``meta.facesvg`` holds what the SVG's metadata holds (frames, camera, options, triangle order), which
``decode`` (the verifier's reader) needs.

Gouraud shading is not written: Lottie's gradient fills are linear or radial between stops, not a triangle's
three vertex colours (the SVG spells those with three overlaid gradients and masks that Lottie has no cheap
equivalent of), so ``--shading gouraud`` with ``--to lottie`` is refused.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from converter.encode import flatplan, groups
from converter.encode.flatplan import STROKE_PX
from converter.encode.groups import BandMotion
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, Report, no_progress, span
from converter.sheet import Sheet
from converter.writers.metadata import source_fields
from converter.writers.svgtext import digits

LOTTIE_VERSION = "5.12.0"  # the bodymovin format version lottie-web 5.x reads without its legacy conversions
FORMAT_VERSION = 1  # of meta.facesvg
GENERATOR = "facesvg"  # meta.g and the dotLottie manifest's generator
ANIMATION_ID = "face"  # the dotLottie's animations/<id>.json
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed zip entry dates: the same bytes for the same input
ZIP_MAGIC = b"PK\x03\x04"
LINEAR = '"i":{"x":1,"y":1},"o":{"x":0,"y":0}'
TANGENTS = '"i":[[0,0],[0,0],[0,0]],"o":[[0,0],[0,0],[0,0]]'
OPAQUE = '"o":{"a":0,"k":100}'
COLOUR_DECIMALS = 3  # 0..1 colour components: 1/2000 is an eighth of a level, so every 8-bit level comes back
BYTES_PER_KEY = 110  # typical text of one shape key (a triangle's 6 integers, its time, tangents, easing)
GROUP_CLOSE = "]}"
ORDER_DONE = 0.02  # progress of the writing when the drawing order is known and the plan starts
KEYS_DONE = 0.8  # progress of the writing when the plan is done and the text starts
HEAVY_ELEMENTS = 2000  # animated shapes past which the report warns (bench_lottie: ThorVG may not load such a file)
TEXT_BLOCK = 512  # elements whose texts are written between two progress calls


# --- numbers ---------------------------------------------------------------------------------------------------
def fixed(units: np.ndarray, decimals: int) -> list[str]:
    """JSON numbers of integers units / 10^decimals, exact, without trailing zeros ('12', '-0.5', '4.9973')."""
    u = np.asarray(units, np.int64).ravel()
    if decimals <= 0:
        return [str(v) for v in (u * 10 ** -decimals if decimals else u).tolist()]
    q = 10 ** decimals
    a = np.abs(u)
    out = []
    for neg, whole, frac in zip((u < 0).tolist(), (a // q).tolist(), (a % q).tolist()):
        text = str(whole) if not frac else f"{whole}.{frac:0{decimals}d}".rstrip("0")
        out.append("-" + text if neg else text)
    return out


def _half_times(half: np.ndarray) -> list[str]:
    """Lottie frame numbers of times in half frames."""
    return fixed(np.asarray(half, np.int64) * 5, 1)


def _colour(levels: np.ndarray) -> str:
    """'[r,g,b]' 0..1 of 8-bit levels (3,)."""
    return "[" + ",".join(fixed(np.rint(np.asarray(levels, np.float64) * (10 ** COLOUR_DECIMALS / 255.0)),
                                COLOUR_DECIMALS)) + "]"


def _colour_property(frames: np.ndarray, levels: np.ndarray) -> str:
    """A colour property of held steps starting at frames (K,) (0 first) with levels (K, 3): static when one."""
    if len(frames) == 1:
        return '{"a":0,"k":' + _colour(levels[0]) + "}"
    times = fixed(np.maximum(2 * np.asarray(frames, np.int64) - 1, 0) * 5, 1)  # half a frame early
    keys = [f'{{"t":{t},"s":{_colour(v)},"h":1}}' for t, v in zip(times, levels)]
    return '{"a":1,"k":[' + ",".join(keys) + "]}"


# --- transforms ------------------------------------------------------------------------------------------------
def _key_frames(frames: np.ndarray, n_frames: int, time_decimals: int) -> list[str]:
    """Lottie frame numbers of a transform's key frames (0..T), at the keyTimes the SVG writes and the plan's
    matrices play: every frame plainly, else kf / T rounded to time_decimals, times T (exact decimals)."""
    kf = np.asarray(frames, np.int64)
    if len(kf) == n_frames + 1:
        return fixed(kf, 0)
    q = 10 ** time_decimals
    return fixed(np.rint(kf * q / n_frames).astype(np.int64) * n_frames, time_decimals)


def _property(times: list[str], rows: list[list[str]], scalar: bool) -> str:
    """A linear Lottie property through values rows (K, D) at times; static when one key."""
    if len(rows) == 1:
        v = rows[0][0] if scalar else "[" + ",".join(rows[0]) + "]"
        return '{"a":0,"k":' + v + "}"
    keys = []
    last = len(rows) - 1
    for i, (t, r) in enumerate(zip(times, rows)):
        keys.append(f'{{"t":{t},"s":[{",".join(r)}]' + ("}" if i == last else f",{LINEAR}}}"))
    return '{"a":1,"k":[' + ",".join(keys) + "]}"


def transform_text(motion: BandMotion, n_frames: int) -> str:
    """The group transform (tr) of a band's played motion: translate -> p (viewBox units), rotate -> r,
    skewX -> sk = -skewX with sa 0, scale -> s in percent; kinds the band does not animate are left out."""
    parts = ['"ty":"tr"', OPAQUE]  # lottie-web draws nothing under a transform without its opacity
    for a in motion.anims:
        times = _key_frames(a.frames, n_frames, motion.time_decimals)
        width = a.values.shape[1]
        units = np.rint(np.asarray(a.values, np.float64) * 10.0 ** a.decimals).astype(np.int64)
        if a.kind == "skewX":
            units = -units
        # scale in percent: the same digits, two decimals fewer
        text = fixed(units, a.decimals - 2) if a.kind == "scale" else fixed(units, a.decimals)
        rows = [text[k:k + width] for k in range(0, len(text), width)]
        key = {"translate": "p", "rotate": "r", "skewX": "sk", "scale": "s"}[a.kind]
        parts.append(f'"{key}":' + _property(times, rows, width == 1))
        if a.kind == "skewX":
            parts.append('"sa":{"a":0,"k":0}')
    return "{" + ",".join(parts) + "}"


def _group_open(motion: BandMotion, n_frames: int) -> str:
    """What a group costs besides its elements: its opening and its transform (what the rigid planner weighs)."""
    return '{"ty":"gr","it":[,' + transform_text(motion, n_frames)


def _group(items: list[str], motion: BandMotion, n_frames: int) -> str:
    """A group of items (document order) under the motion's transform: Lottie's list is the reverse, tr last."""
    return '{"ty":"gr","it":[' + ",".join([*reversed(items), transform_text(motion, n_frames)]) + GROUP_CLOSE


# --- shapes ----------------------------------------------------------------------------------------------------
def _shape_value(row: list[int], closed: bool) -> str:
    """One triangle as a Lottie bezier (straight edges: zero tangents)."""
    x0, y0, x1, y1, x2, y2 = row
    shut = '"c":true,' if closed else ""
    return f'{{{shut}"v":[[{x0},{y0}],[{x1},{y1}],[{x2},{y2}]],{TANGENTS}}}'


def shape_text(rows: np.ndarray, half: np.ndarray, closed: bool) -> str:
    """A path (sh) through integer triangles rows (K, 6) at half-frame times half (K,); static when it never
    moves."""
    vals = rows.tolist()
    if all(v == vals[0] for v in vals[1:]):
        return '{"ty":"sh","ks":{"a":0,"k":' + _shape_value(vals[0], closed) + "}}"
    times = _half_times(half)
    last = len(vals) - 1
    keys = [f'{{"t":{t},"s":[{_shape_value(v, closed)}]' + ("}" if i == last else f",{LINEAR}}}")
            for i, (t, v) in enumerate(zip(times, vals))]
    return '{"ty":"sh","ks":{"a":1,"k":[' + ",".join(keys) + "]}}"


def offset(rows: np.ndarray) -> np.ndarray | None:
    """A static integer position (2,) for an element's key rows (K, n * 6), the median of its first points, where
    the digits it saves its coordinates outweigh its transform's text; else None. Gzip keeps little of the text
    Lottie repeats per key but most of the digits, so digits are what a deflated Lottie weighs (bench_lottie)."""
    at = np.median(rows[:, 0:2], axis=0).astype(np.int64)
    moved = rows - np.tile(at, rows.shape[1] // 2)
    saved = int(digits(rows).sum() - digits(moved).sum())
    return at if saved > len(_position(at)) - len(_position(None)) else None


def _position(at: np.ndarray | None) -> str:
    """An element's transform (tr): its static position at, else none; lottie-web draws a group only with a
    transform, and the transform only with its opacity."""
    if at is None:
        return f'{{"ty":"tr",{OPAQUE}}}'
    return f'{{"ty":"tr","p":{{"a":0,"k":[{at[0]},{at[1]}]}},{OPAQUE}}}'


def element_text(shapes: list[str], colour: str, stroke_width: str, bare: bool, at: np.ndarray | None = None) -> str:
    """One element's group: its paths, its stroke (unless bare: above the fill, as SVG paints it), its fill and
    its transform: the static position at (else none)."""
    items = list(shapes)
    if not bare:
        items.append(f'{{"ty":"st","c":{colour},{OPAQUE},"w":{{"a":0,"k":{stroke_width}}},"lc":2,"lj":2}}')
    items.append(f'{{"ty":"fl","c":{colour},{OPAQUE},"r":1}}')
    items.append(_position(at))
    return '{"ty":"gr","it":[' + ",".join(items) + "]}"


# --- the document ----------------------------------------------------------------------------------------------
def _check(options: ConversionOptions) -> None:
    """InputError for what Lottie output cannot do."""
    if options.shading != "flat":
        raise InputError("Lottie output is flat-shaded only (its gradients cannot carry a triangle's three vertex "
                         "colours); use --shading flat or --to svg for Gouraud shading.")
    if options.raw:
        raise InputError("--raw is the SVG's unoptimised encoding; Lottie output is always error-bounded: drop "
                         "--raw or use --to svg.")


def _root(sheet: Sheet, options: ConversionOptions, scale: int, layers: list[str], meta: dict,
          n_frames: int) -> str:
    """The animation object around its layers, with facesvg's metadata under meta.facesvg."""
    w, h = sheet.camera.width, sheet.camera.height
    fps = float(sheet.fps)
    head = {"v": LOTTIE_VERSION, "fr": int(fps) if fps.is_integer() else fps, "ip": 0, "op": n_frames, "w": w,
            "h": h, "nm": sheet.name, "ddd": 0, "assets": []}
    info = {"g": GENERATOR, "facesvg": meta}
    text = json.dumps(head, separators=(",", ":"))[:-1]
    return (text + ',"layers":[' + ",".join(layers) + '],"meta":'
            + json.dumps(info, sort_keys=True, separators=(",", ":")) + "}")


def _layer(shapes: list[str], scale: int, n_frames: int) -> str:
    """The shape layer holding every element: a static scale from viewBox units to px."""
    pct = repr(100.0 / scale) if scale != 1 else "100"
    ks = (f'{{"a":{{"a":0,"k":[0,0]}},"p":{{"a":0,"k":[0,0]}},"s":{{"a":0,"k":[{pct},{pct}]}},'
          f'"r":{{"a":0,"k":0}},{OPAQUE}}}')
    return (f'{{"ddd":0,"ind":1,"ty":4,"nm":"face","sr":1,"ks":{ks},"ao":0,"ip":0,"op":{n_frames},"st":0,'
            f'"bm":0,"shapes":[' + ",".join(shapes) + "]}")


def _meta(sheet: Sheet, options: ConversionOptions, order: np.ndarray, encoding: dict) -> dict:
    """What the SVG's metadata says (svg_anim.metadata), for the verifier."""
    return {"format": "facesvg", "version": FORMAT_VERSION, **source_fields(sheet, options),
            "triangle_order": [int(i) for i in order], "encoding": encoding}


def write(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The Lottie JSON of the flat plan (or the one-frame Lottie of options.frame)."""
    _check(options)
    if options.frame is not None:
        return write_still(sheet, options, report, options.frame)
    return encode(sheet, options, report, progress)


def write_dotlottie(sheet: Sheet, options: ConversionOptions, report: Report,
                    progress: Progress = no_progress) -> bytes:
    """The dotLottie (.lottie) zip of write's animation: manifest.json and animations/<id>.json."""
    anim = write(sheet, options, report, progress)
    report.sizes["lottie_json"] = len(anim)
    return package(anim)


def package(anim: bytes) -> bytes:
    """A dotLottie zip (deflated, fixed dates) holding the Lottie JSON anim as its one animation."""
    manifest = {"version": "1", "generator": GENERATOR, "author": "facesvg",
                "animations": [{"id": ANIMATION_ID, "speed": 1, "loop": True, "autoplay": True}]}
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for name, data in (("manifest.json", json.dumps(manifest, sort_keys=True, separators=(",", ":")).encode()),
                           (f"animations/{ANIMATION_ID}.json", anim)):
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, data, compresslevel=9)
    return out.getvalue()


def write_still(sheet: Sheet, options: ConversionOptions, report: Report, frame: int) -> bytes:
    """One frame as static paths (flatplan.still: exact colours, coordinates on the tolerance's grid), one frame
    long."""
    fs = flatplan.still(sheet, options, frame)
    scale, tris, levels, q, closed, bare = fs.scale, fs.tris, fs.levels, fs.corners, fs.closed, fs.bare
    width = fixed(np.array([round(STROKE_PX * scale * 1000)]), 3)[0]
    items = [element_text([shape_text(q[j:j + 1], np.zeros(1, np.int64), bool(closed[j]))],
                          _colour_property(np.zeros(1, np.int64), levels[j:j + 1]), width, bool(bare[j]))
             for j in range(len(tris))]
    meta = _meta(sheet, options, tris, {"mode": "still", "scale": scale, "frame": frame})
    report.counts["paths"] = len(tris)
    return _root(sheet, options, scale, [_layer(items[::-1], scale, 1)], meta, 1).encode("utf-8")


class _Element(NamedTuple):
    """An element of the plan: its paths [first, last) and, for a merged one, its band and row there."""

    first: int
    last: int
    band: int  # index into FlatPlan.merged, -1 for a single path
    row: int  # row of the band's timeline (its index in band.sets)


def _elements(fp: flatplan.FlatPlan) -> list[_Element]:
    """Every element in document order."""
    where = {}
    for b, band in enumerate(fp.merged):
        for row, k in enumerate(band.sets.tolist()):
            where[k] = (b, row)
    sets = {a: k for k, (a, _) in enumerate(fp.sets)}
    s = fp.starts.tolist()
    out = []
    for a, b in zip(s[:-1], s[1:]):
        band, row = where[sets[a]] if a in sets else (-1, -1)
        out.append(_Element(a, b, band, row))
    return out


def _held(frames: np.ndarray, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Held steps (frames (K,), levels (K, 3)) without those that do not change the colour."""
    keep = np.ones(len(frames), bool)
    keep[1:] = (levels[1:] != levels[:-1]).any(axis=1)
    return frames[keep], levels[keep]


def _colours(fp: flatplan.FlatPlan, t: int) -> tuple[list[str], int, int]:
    """Per path its fill colour property text, the colour keys written (per element: the first path's) and the
    palette entries used. Steps at the loop end (frame T) are never shown and not written."""
    if fp.shared is not None:
        shared = fp.shared
        texts: dict[int, tuple[str, int]] = {}
        for e in np.unique(shared.entry).tolist():
            f = np.flatnonzero(shared.mask[:t, e])
            f, v = _held(f, shared.values[f, e].astype(np.int64))
            texts[e] = (_colour_property(f, v), len(f))
        out = [texts[e][0] for e in shared.entry.tolist()]
        return out, sum(texts[shared.entry[a]][1] for a in fp.starts[:-1].tolist()), len(texts)
    steps = fp.steps
    pk, fk = np.nonzero(steps.mask[:t].T)
    vals = steps.values.transpose(1, 0, 2)[pk, fk].astype(np.int64)
    bounds = np.searchsorted(pk, np.arange(fp.n_paths + 1)).tolist()
    out, counts = [], []
    for j in range(fp.n_paths):
        f, v = _held(fk[bounds[j]:bounds[j + 1]], vals[bounds[j]:bounds[j + 1]])
        out.append(_colour_property(f, v))
        counts.append(len(f))
    return out, sum(counts[a] for a in fp.starts[:-1].tolist()), 0


def encode(sheet: Sheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The Lottie JSON of the bounded flat plan; progress(stage, fraction of the writing) as it goes."""
    t = sheet.n_frames
    progress("order", 0.0)
    costs = groups.Costs(lambda m: len(_group_open(m, t)), len(GROUP_CLOSE), BYTES_PER_KEY)
    fp = flatplan.plan(sheet, options, "bounded", costs, span(progress, ORDER_DONE, KEYS_DONE))
    text = span(progress, KEYS_DONE, 1.0, "text")
    text("text", 0.0)
    tl = fp.timeline
    fp.track = fp.timeline = None
    scale = fp.budget.scale
    tris, plan = fp.tris, fp.rigid
    closed, bare = fp.strokes.closed(tris), fp.strokes.bare(tris)
    bounds = np.searchsorted(tl.path, np.arange(fp.n_paths + 1))
    colours, n_colour_keys, entries = _colours(fp, t)
    width = fixed(np.array([round(STROKE_PX * scale * 1000)]), 3)[0]
    merged_rows = [np.rint(np.asarray(b.timeline.values, np.float64) * scale).astype(np.int64) for b in fp.merged]
    merged_bounds = [np.searchsorted(b.timeline.path, np.arange(len(b.sets) + 1)) for b in fp.merged]
    opens: dict[int, int] = {}
    closes: set[int] = set()
    if plan is not None:
        for a, b in plan.groups.tolist():
            opens[a] = int(plan.band[a])
            closes.add(b - 1)
    elements = _elements(fp)
    items: list[str] = []  # the head's contents, document order
    run: list[str] | None = None
    run_band = -1
    n_keys = static = 0
    for i, el in enumerate(elements):
        if i % TEXT_BLOCK == 0:
            text("text", i / max(len(elements), 1))
        if el.first in opens:
            run, run_band = [], opens[el.first]
        if el.band < 0:
            lo, hi = bounds[el.first], bounds[el.first + 1]
            rows = np.rint(np.asarray(tl.values[lo:hi], np.float64) * scale).astype(np.int64)
            half = tl.half[lo:hi]
        else:
            lo, hi = merged_bounds[el.band][el.row], merged_bounds[el.band][el.row + 1]
            rows = merged_rows[el.band][lo:hi, :6 * (el.last - el.first)]
            half = fp.merged[el.band].timeline.half[lo:hi]
        at = offset(rows)
        if at is not None:
            rows = rows - np.tile(at, rows.shape[1] // 2)
        shapes = [shape_text(rows[:, 6 * s:6 * s + 6], half, bool(closed[j]))
                  for s, j in enumerate(range(el.first, el.last))]
        moving = [sh for sh in shapes if sh.startswith('{"ty":"sh","ks":{"a":1')]
        n_keys += (hi - lo) if moving else 1
        static += not moving
        body = element_text(shapes, colours[el.first], width, bool(bare[el.first]), at)
        (run if run is not None else items).append(body)
        if run is not None and el.last - 1 in closes:
            items.append(_group(run, plan.motions[run_band], t))
            run = None
    shapes_out = [_group(items, plan.head, t)] if plan is not None else items[::-1]
    encoding = {"mode": "bounded", "scale": scale, "tolerance": fp.budget.tolerance,
                "color_levels": options.color_tolerance, "hidden": "collapsed"}
    if plan is not None:
        encoding["rigid"] = {"groups": len(opens), "max_gain": round(plan.stats["max_gain"], 6)}
    meta = _meta(sheet, options, tris, encoding)
    out = _root(sheet, options, scale, [_layer(shapes_out, scale, t)], meta, t).encode("utf-8")
    _report(report, sheet, fp, len(elements), n_keys, static, n_colour_keys, entries)
    text("text", 1.0)
    return out


def _report(report: Report, sheet: Sheet, fp: flatplan.FlatPlan, n_elements: int, n_keys: int, static: int,
            n_colour_keys: int, entries: int) -> None:
    """The SVG writer's counts and figures for the Lottie document."""
    tris = fp.tris
    report.counts["paths"] = n_elements
    report.counts["keys"] = int(n_keys)
    if n_elements > HEAVY_ELEMENTS:
        report.warnings.append(
            f"this Lottie animates {n_elements:,} shapes: native players slow down with thousands of animated paths "
            "and ThorVG may not load it; --preset mobile makes one for apps (bench_lottie measures both).")
    report.counts["static_paths"] = static
    report.counts["animated_paths"] = n_elements - static
    report.counts["color_keys"] = n_colour_keys
    report.counts["depth_conflicts"] = fp.conflicts
    report.counts["depth_conflicts_left"] = fp.residual
    report.counts["layer_copies"] = int(len(tris) - len(np.unique(tris)))
    report.figures["keys_per_path"] = float(n_keys / max(fp.n_paths, 1))
    if fp.sets:
        report.counts["merged_paths"] = len(fp.sets)
        report.counts["merged_triangles"] = int(len(flatplan.merged_paths(fp.sets)))
    if fp.shared is not None:
        report.counts["palette_entries"] = entries
    err = fp.colour_error(sheet)
    report.figures["color_error_max_levels"] = float(err.max(initial=0.0))
    if fp.rigid is not None:
        report.counts.update({f"rigid_{k}": int(v) for k, v in fp.rigid.stats.items() if k != "max_gain"})


# --- the reader (facesvg verify) -------------------------------------------------------------------------------
class Decoded(NamedTuple):
    """A facesvg Lottie evaluated at its frames 0..T-1."""

    meta: dict
    triangles: np.ndarray  # int64 (P,) input triangle of each path, back to front
    xy: np.ndarray  # float64 (T, P, 3, 2) px
    shown: np.ndarray  # bool (T, P) drawn (not collapsed to a point)
    collapsed: np.ndarray  # bool (T, P) collapsed to a point (hidden)
    rgb: np.ndarray  # float64 (T, P, 3) fill colour, 8-bit levels
    stroked: np.ndarray  # bool (P,) the path's element has a stroke
    closed: np.ndarray  # bool (P,)


def is_lottie(data: bytes) -> bool:
    """Whether the bytes look like a Lottie JSON document or a dotLottie zip (not an SVG or a player)."""
    return data[:4] == ZIP_MAGIC or data.lstrip()[:1] == b"{"


def animation_json(data: bytes) -> dict:
    """The Lottie animation of JSON bytes or of a dotLottie zip (its manifest's first animation)."""
    if data[:4] == ZIP_MAGIC:
        try:
            with zipfile.ZipFile(io.BytesIO(data)) as z:
                manifest = json.loads(z.read("manifest.json"))
                first = manifest["animations"][0]["id"]
                names = [f"animations/{first}.json", f"a/{first}.json"]
                name = next((n for n in names if n in z.namelist()), None)
                if name is None:
                    raise KeyError(first)
                data = z.read(name)
        except (zipfile.BadZipFile, KeyError, IndexError, TypeError, ValueError):
            raise InputError("the .lottie file is not a dotLottie zip with a manifest and its animation; "
                             "regenerate it.") from None
    try:
        doc = json.loads(data)
    except (UnicodeDecodeError, ValueError):
        raise InputError("the Lottie file is not valid JSON; regenerate it.") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("layers"), list):
        raise InputError("the file is not a Lottie animation (no layers); only facesvg output can be verified.")
    return doc


def _static_or_keys(prop: dict, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (K,), values (K, width), hold (K,)) of a property with scalar or vector values."""
    if not prop.get("a"):
        v = np.atleast_1d(np.asarray(prop["k"], np.float64))
        return np.zeros(1), v[None, :width], np.zeros(1, bool)
    keys = prop["k"]
    times = np.array([k["t"] for k in keys], np.float64)
    vals = np.array([np.atleast_1d(np.asarray(k["s"], np.float64))[:width] for k in keys])
    hold = np.array([bool(k.get("h")) for k in keys])
    _check_linear(keys, hold)
    return times, vals, hold


def _check_linear(keys: list[dict], hold: np.ndarray) -> None:
    """InputError unless every segment's easing is linear (a handle on the diagonal)."""
    for k, h in zip(keys[:-1], hold[:-1].tolist()):
        if h:
            continue
        try:
            ix, iy, ox, oy = (np.asarray(k[a][b], np.float64) for a in ("i", "o") for b in ("x", "y"))
        except KeyError:
            raise InputError("a Lottie keyframe has no easing; the file is corrupt.") from None
        if not (np.allclose(ix, iy) and np.allclose(ox, oy)):
            raise InputError("the Lottie file has eased (non-linear) keyframes; only facesvg output can be verified.")


def evaluate_keys(times: np.ndarray, values: np.ndarray, hold: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Values (T, D) of keys at frames as Lottie players play them: the first key before it, the last after it,
    held after a hold key, else linear."""
    k = len(times)
    if k == 1:
        return np.broadcast_to(values[0], (len(frames), values.shape[1])).copy()
    i = np.clip(np.searchsorted(times, frames, side="right") - 1, 0, k - 2)
    span_ = times[i + 1] - times[i]
    frac = np.clip((frames - times[i]) / np.where(span_ > 0, span_, 1.0), 0.0, 1.0)
    frac = np.where(hold[i] & (frames < times[i + 1]), 0.0, frac)
    return values[i] + frac[:, None] * (values[i + 1] - values[i])


def _matrices(tr: dict | None, frames: np.ndarray) -> np.ndarray:
    """(T, 3, 3) of a Lottie transform at frames: T(p) R(r) R(-sa) Kx(-sk) R(sa) S(s / 100) T(-a)."""
    n = len(frames)
    out = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    if not tr:
        return out

    def get(key: str, default: list[float]) -> np.ndarray:
        if key not in tr:
            return np.broadcast_to(np.asarray(default, np.float64), (n, len(default)))
        return evaluate_keys(*_static_or_keys(tr[key], len(default)), frames)

    def stack(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, e=None, f=None) -> np.ndarray:
        m = np.zeros((n, 3, 3))
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1], m[:, 2, 2] = a, b, c, d, 1.0
        if e is not None:
            m[:, 0, 2], m[:, 1, 2] = e, f
        return m

    def rot(deg: np.ndarray) -> np.ndarray:
        r = np.radians(deg)
        return stack(np.cos(r), -np.sin(r), np.sin(r), np.cos(r))

    one, zero = np.ones(n), np.zeros(n)
    a, p, s = get("a", [0.0, 0.0]), get("p", [0.0, 0.0]), get("s", [100.0, 100.0])
    r, sk, sa = get("r", [0.0])[:, 0], get("sk", [0.0])[:, 0], get("sa", [0.0])[:, 0]
    move = stack(one, zero, zero, one, p[:, 0], p[:, 1])
    skew = stack(one, np.tan(np.radians(-sk)), zero, one)
    size = stack(s[:, 0] / 100, zero, zero, s[:, 1] / 100)
    anchor = stack(one, zero, zero, one, -a[:, 0], -a[:, 1])
    return move @ rot(r) @ rot(-sa) @ skew @ rot(sa) @ size @ anchor


def _shape_track(prop: dict, frames: np.ndarray) -> tuple[np.ndarray, bool]:
    """A path's vertices (T, 3, 2) at frames and whether it is closed; InputError unless a triangle."""
    if prop.get("a"):
        keys = prop["k"]
        shapes = [k["s"][0] for k in keys]
        times = np.array([k["t"] for k in keys], np.float64)
        hold = np.array([bool(k.get("h")) for k in keys])
        _check_linear(keys, hold)
    else:
        shapes, times, hold = [prop["k"]], np.zeros(1), np.zeros(1, bool)
    try:
        vals = np.array([np.asarray(s["v"], np.float64).reshape(6) for s in shapes])
    except (KeyError, ValueError, TypeError):
        raise InputError("a Lottie path is not a facesvg triangle; only facesvg output can be verified.") from None
    return evaluate_keys(times, vals, hold, frames).reshape(len(frames), 3, 2), bool(shapes[0].get("c"))


def _elements_of(items: list, mat: np.ndarray, frames: np.ndarray) -> Iterator[tuple[list[dict], dict | None,
                                                                                        bool, np.ndarray]]:
    """Per element group under items (a shape list, top first), back to front: its paths, fill, whether it is
    stroked and its matrices (T, 3, 3) to px."""
    tr = next((it for it in reversed(items) if it.get("ty") == "tr"), None)
    mat = mat @ _matrices(tr, frames) if tr is not None else mat
    paths = [it for it in items if it.get("ty") == "sh"]
    if paths:
        fill = next((it for it in items if it.get("ty") == "fl"), None)
        yield paths, fill, any(it.get("ty") == "st" for it in items), mat
    for it in reversed(items):
        if it.get("ty") == "gr":
            yield from _elements_of(it.get("it", []), mat, frames)


def _facesvg_meta(doc: dict) -> dict:
    """meta.facesvg of a Lottie animation; InputError when absent."""
    meta = doc["meta"].get("facesvg") if isinstance(doc.get("meta"), dict) else None
    if not isinstance(meta, dict):
        raise InputError("the Lottie file has no facesvg metadata (meta.facesvg); only facesvg output can be "
                         "verified.")
    return meta


def metadata(data: bytes) -> dict:
    """The facesvg metadata (frames, camera, options, triangle order) of a Lottie or dotLottie file."""
    return _facesvg_meta(animation_json(data))


def decode(data: bytes) -> Decoded:
    """A facesvg Lottie (JSON or dotLottie) evaluated at every frame of its source: positions, visibility and
    colours of every path; InputError when it is not facesvg output."""
    doc = animation_json(data)
    meta = _facesvg_meta(doc)
    try:
        n_frames = int(meta["frames"])
        order = [int(i) for i in meta["triangle_order"]]
    except (KeyError, TypeError, ValueError):
        raise InputError("the facesvg metadata lacks frames or triangle_order; the file is corrupt.") from None
    frames = np.arange(n_frames, dtype=np.float64)
    xy, rgb, stroked, closed, ids = [], [], [], [], []
    at = 0
    try:
        for layer in reversed(doc["layers"]):
            if layer.get("ty") != 4:
                continue
            base = _matrices(layer.get("ks"), frames)
            for paths, fill, has_stroke, mat in _elements_of(layer.get("shapes", []), base, frames):
                colour = (evaluate_keys(*_static_or_keys(fill["c"], 3), frames) * 255 if fill is not None
                          else np.zeros((n_frames, 3)))
                for sh in paths:
                    pts, shut = _shape_track(sh["ks"], frames)
                    xy.append(np.einsum("tij,tvj->tvi", mat[:, :2, :2], pts) + mat[:, None, :2, 2])
                    rgb.append(colour)
                    stroked.append(has_stroke)
                    closed.append(shut)
                    if at >= len(order):
                        raise InputError("the Lottie file holds more paths than its metadata's triangle_order "
                                         "lists; the file is corrupt.")
                    ids.append(order[at])
                    at += 1
    except (KeyError, TypeError, IndexError, AttributeError):
        raise InputError("the Lottie file's layers are not facesvg's; only facesvg output can be verified.") from None
    if not xy:
        raise InputError("the Lottie file has no paths; only facesvg output can be verified.")
    pos = np.stack(xy, axis=1)
    point = (pos == pos[:, :, :1]).all(axis=(2, 3))
    return Decoded(meta, np.array(ids, np.int64), pos, ~point, point, np.stack(rgb, axis=1),
                   np.array(stroked), np.array(closed))

