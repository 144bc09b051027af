"""Fewer animated elements: runs of paths of one static colour merged into one <path> of several subpaths.

A player's cost per frame grows with the number of animated elements (bench_playback: the mobile-preset
capture-like face plays in Chromium under CPU throttling markedly faster with the same triangles in fewer paths;
BENCHMARKS.md, playback in Chromium under CPU throttling). Under an explicit budget (``--max-animations N``) the
flat SVG writer merges paths that:

- sit in the same group (the rigid planner's runs, converter.encode.groups), so one transform moves them all;
- have one static colour: their middle shade's entry in a median-cut palette (PALETTES, largest first) where
  the colour tolerance allows, else their exact middle shade must agree;
- wind the same way wherever they are shown, so the nonzero fill of overlapping subpaths never cancels.

Within each group the paths are reordered (``by_runs``) so that paths of one colour follow each other, keeping
the order of every pair whose interiors may overlap (``overlap_pairs`` with converter.encode.order's margin):
wherever one triangle covers another the painter's order is unchanged; neighbours that only touch may swap,
which moves which of their 0.5 px seam strokes lies on top. A run of one colour is then cut into sets of at
most ``size`` neighbours (Z-order of their mean positions). The palette and sizes are the largest and
smallest that bring the elements under the budget. The writer keys each set's subpaths together (one keyTimes list,
free knots over all its points), so the colour error (reported) and the extra bytes (bench_playback's files)
are what the budget costs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from PIL import Image

from converter.encode.order import OVERLAP_MARGIN_PX, greedy_order
from converter.encode.overlap import overlap_pairs

PALETTES = (256, 128, 64, 48, 32, 24, 16)  # colours of the merged paths' palette tried, finest first
SIZES = (2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)  # paths per set tried, smallest first


class Merge(NamedTuple):
    """Which paths (in document order after ``order``) are drawn as one element, and in which colour."""

    order: np.ndarray  # int (P,) permutation of the writer's paths
    starts: np.ndarray  # int (E + 1,) first path of each element, then P (consecutive paths share an element)
    levels: np.ndarray  # int (P, 3) static colour of each path (new order) where mergeable, -1 elsewhere
    size: int  # most paths in one element
    colours: int  # most colours of the merged paths' palette


def colour_codes(rgb: np.ndarray, active: np.ndarray, tolerance: float, colours: int) -> tuple[np.ndarray, np.ndarray]:
    """Per path (rgb (T, P, 3) in 0..1, shown where active) its mergeable static colour as levels (P, 3) and a
    code (P,): its middle shade's entry in a median-cut palette of at most `colours` (Pillow; it keeps the
    hues of the face, where rounding each channel on a grid turned skin green and pink) where all its shades
    stay within tolerance levels of that, else the middle shade itself where they stay within it, else -1."""
    levels = np.asarray(rgb, np.float64) * 255
    lo = np.where(active[..., None], levels, np.inf).min(axis=0)
    hi = np.where(active[..., None], levels, -np.inf).max(axis=0)
    shown = active.any(axis=0)
    lo, hi = np.where(shown[:, None], lo, 0.0), np.where(shown[:, None], hi, 0.0)
    mid = np.clip(np.rint((lo + hi) / 2), 0, 255)
    coarse = mid
    if len(mid) and colours < 256:
        image = Image.fromarray(mid.astype(np.uint8).reshape(1, -1, 3))
        q = image.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        palette = np.array(q.getpalette()[:3 * colours], np.float64).reshape(-1, 3)
        coarse = palette[np.asarray(q).ravel()]
    err = lambda c: np.maximum(np.abs(c - lo), np.abs(hi - c)).max(axis=1)  # noqa: E731
    colour = np.where((err(coarse) <= tolerance)[:, None], coarse, mid).astype(np.int64)
    ok = shown & (err(colour) <= tolerance)
    code = np.where(ok, (colour[:, 0] << 16) | (colour[:, 1] << 8) | colour[:, 2], -1)
    return np.where(ok[:, None], colour, -1), code


def winding(xy_paths: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Per path (xy_paths (T, P, 3, 2)) the sign of its area wherever shown: +1, -1, or 0 when it changes."""
    a = xy_paths
    e1, e2 = a[:, :, 1] - a[:, :, 0], a[:, :, 2] - a[:, :, 0]
    area = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    pos = ((area > 0) | ~active).all(axis=0)
    neg = ((area < 0) | ~active).all(axis=0)
    return np.where(pos, 1, np.where(neg, -1, 0)).astype(np.int8)


def by_runs(key: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """A draw order (permutation) of paths with keys (P,) that keeps every pair (first before second) and draws
    long runs of one key: it continues the current key while one of its paths is free, then takes the key with
    the most free paths (the earliest on ties). Paths of one key need no order among themselves: one colour
    over itself looks the same either way."""
    return greedy_order(key, pairs, lambda free: max((len(h), -h[0], k) for k, h in free.items() if h)[2])


def _sets(segment: np.ndarray, key: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The by_runs order within each segment (pairs of one key dropped) and the start of each run of one key."""
    p = len(key)
    order = np.arange(p)
    cross = pairs[key[pairs[:, 0]] != key[pairs[:, 1]]]
    edges = np.concatenate([[0], np.flatnonzero(np.diff(segment)) + 1, [p]]).tolist()
    for a, b in zip(edges[:-1], edges[1:]):
        inside = (cross >= a).all(axis=1) & (cross < b).all(axis=1)
        _, local = np.unique(key[a:b], return_inverse=True)
        order[a:b] = a + by_runs(local.ravel(), cross[inside] - a)
    k, seg = key[order], segment[order]
    start = np.ones(p, bool)
    start[1:] = (k[1:] != k[:-1]) | (seg[1:] != seg[:-1]) | (k[1:] < 0)
    return order, np.concatenate([np.flatnonzero(start), [p]])


def _z_order(xy: np.ndarray) -> np.ndarray:
    """Morton code (P,) of points (P, 2) on a 1024 x 1024 grid over their bounding box."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    cell = np.clip(((xy - lo) / np.maximum(hi - lo, 1e-9) * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(xy), np.int64)
    for bit in range(10):
        code |= ((cell[:, 0] >> bit) & 1) << (2 * bit) | ((cell[:, 1] >> bit) & 1) << (2 * bit + 1)
    return code


def plan(segment: np.ndarray, rgb: np.ndarray | None, active: np.ndarray, tolerance: float, xy_paths: np.ndarray,
         max_elements: int, entries: np.ndarray | None = None, max_size: int | None = None) -> Merge:
    """Merge sets for paths (document order) in groups segment (P,), with shades rgb (T, P, 3) within colour
    tolerance levels, drawn at xy_paths (T, P, 3, 2) where active (T, P): the largest palette, then the
    smallest sets, that leave at most max_elements elements (the smallest palette and largest sets tried when
    none does). With entries (P,), each path's animated palette entry (converter.encode.palette) is its colour
    instead: paths of one entry merge (levels then holds the entry in its first column, -1 in the others).
    max_size: the largest set tried (default: every size in SIZES)."""
    sizes = [s for s in SIZES if max_size is None or s <= max_size] or [1]
    p = len(segment)
    sign = winding(xy_paths, active)
    # Interiors that overlap keep their order; neighbours that only touch may swap (their seam strokes do).
    pairs = overlap_pairs(xy_paths, active, margin=-OVERLAP_MARGIN_PX) if p > 1 else np.zeros((0, 2), np.int64)
    for colours in PALETTES if entries is None else (0,):
        if entries is None:
            levels, code = colour_codes(rgb, active, tolerance, colours)
        else:
            code = np.asarray(entries, np.int64)
            levels = np.stack([code, np.full(p, -1), np.full(p, -1)], axis=1)
        key = np.where((code >= 0) & (sign != 0), code * 2 + (sign > 0), -1)
        key = np.where(key >= 0, key, -1 - np.arange(p))  # an unmergeable path is a key of its own
        order, runs = _sets(segment, key, pairs)
        lengths = np.diff(runs)
        for size in sizes:
            if int((-(-lengths // size)).sum()) <= max_elements:
                break
        if int((-(-lengths // size)).sum()) <= max_elements:
            break
    # Paths of one run may go in any order: neighbours go together (along a Z-order curve of their mean
    # position), since they move alike and a set's keys follow its busiest path.
    centre = xy_paths.mean(axis=(0, 2), dtype=np.float64)[order]  # (P, 2)
    run_of = np.repeat(np.arange(len(lengths)), lengths)
    order = order[np.lexsort((_z_order(centre), run_of))]
    starts = [np.linspace(a, a + n, -(-n // size) + 1).round().astype(np.int64)[:-1]
              for a, n in zip(runs[:-1].tolist(), lengths.tolist())]
    out = np.concatenate(starts + [np.array([p], np.int64)])
    return Merge(order, out, levels[order], size, colours)
