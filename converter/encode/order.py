"""Drawing order when depth order changes during the animation (head turns, jaw opening in front of teeth).

An SVG draws its paths in one fixed order (painter's algorithm), but which of two overlapping triangles is in
front can change from frame to frame. What we do and what we measured (bench/bench_svg.py, "depth order"):

1. Back-face and frustum culling per frame (converter.extract) removes most overlaps: on a face, two
   front-facing triangles overlap only across a fold (nose over cheek when the head turns, lips over teeth,
   eyelids over the eyeballs). Culled triangles are hidden by the class animation at exactly those frames.
2. The fixed order is the painter's order of the neutral frame (centroid NDC depth, back to front). The
   alternative we measured, mean depth over the frames where each triangle is visible, is bench/order_measure.py's
   ``robust_order``.
3. ``layered`` (experimental, not the default): find pairs of triangles whose interiors overlap at some sampled
   frame (converter.encode.overlap's pair search; pairs sharing a vertex skipped), decide which is nearer where
   they overlap (both depth planes compared at probe points inside both), and give a triangle that must cover a
   later-drawn one a second path drawn after it, shown only at those frames while the original is hidden there
   (animated visibility).

The error left is measured against a z-buffer (bench/order_measure.py, ``order_error``): pyrender renders
triangle ids, resvg renders the same frame's SVG with ids as colours, and we count covered interior pixels
(away from anti-aliased edges) whose front triangle differs. On the ICT faces (head turns up to +-40 degrees)
the fixed neutral-frame order leaves few such pixels wrong, as few as a per-frame painter's sort; the
experimental layer copies fix a triangle crossing in front of another (tests) but made the faces worse, so
the default is the fixed order; see BENCHMARKS.md for the figures.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy import sparse

from converter.arrays import unique_ints
from converter.encode.overlap import overlap_pairs
from converter.sheet import Sheet

OVERLAP_MARGIN_PX = 0.25  # interiors must overlap by this much along every axis (neighbours only touch)
SAMPLE_FRAMES = 16  # overlapping pairs are searched at about this many frames
CHUNK = 4000  # pairs tested together
SHORT_ROW = 8  # greedy_order releases a popped path's successors one by one up to this many, else with numpy


class DrawList(NamedTuple):
    """Paths in document (painter's) order: the triangle each draws and the frames where it shows."""

    triangles: np.ndarray  # int32 (P,) triangle id per path, back to front; a triangle may appear twice
    active: np.ndarray  # bool (T, P) the path is shown at frame k
    conflicts: int = 0  # (pair, frame) conflicts of the base order
    residual: int = 0  # (pair, frame) conflicts left after the layer copies


def overlapping_pairs(sheet: Sheet, tris: np.ndarray, frames: np.ndarray,
                      active: np.ndarray | None = None) -> np.ndarray:
    """(M, 2) positions into tris (first < second) of paths whose interiors overlap by more than
    OVERLAP_MARGIN_PX at one of the frames (both shown there); pairs sharing a vertex are left out.

    The pair search is converter.encode.overlap's, frame by frame (blocks of one frame) with a negative margin:
    "within -m px" is "overlapping by more than m" along each separating axis."""
    fr = np.asarray(frames, np.int64)
    shown = np.take(sheet.visible, tris, axis=1) if active is None else active
    f = sheet.faces[tris]
    pairs = overlap_pairs(np.take(sheet.xy[fr], f, axis=1), shown[fr], block=1, margin=-OVERLAP_MARGIN_PX)
    shared = (f[pairs[:, 0], :, None] == f[pairs[:, 1], None, :]).any(axis=(1, 2))
    return pairs[~shared]


def greedy_order(key: np.ndarray, pairs: np.ndarray, switch: Callable[[dict[int, list[int]]], int]) -> np.ndarray:
    """A topological order (permutation) of paths with keys (P,) keeping every pair (first before second) that
    draws runs of one key: the current key goes on while one of its paths is free (the lowest index first),
    then switch(free) names the next key (free: key -> heap of its free paths, some empty)."""
    p = len(key)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    code = unique_ints(pairs[:, 0] * p + pairs[:, 1])
    first = code // p
    second = code - first * p
    succ = sparse.csr_matrix((np.ones(len(code), bool), (first, second)), shape=(p, p))
    indeg = np.bincount(second, minlength=p) if len(code) else np.zeros(p, np.int64)
    free: dict[int, list[int]] = {}
    for i in np.flatnonzero(indeg == 0).tolist():
        heapq.heappush(free.setdefault(int(key[i]), []), i)
    order: list[int] = []
    cur = None
    indptr, indices = succ.indptr, succ.indices
    kl = key.tolist()
    while len(order) < p:
        if not free.get(cur):
            cur = switch(free)
        i = heapq.heappop(free[cur])
        order.append(i)
        succ_i = indices[indptr[i]:indptr[i + 1]]  # distinct (the pairs are deduplicated), ascending
        if len(succ_i) > SHORT_ROW:
            indeg[succ_i] -= 1
            ready = succ_i[indeg[succ_i] == 0].tolist()
        else:
            ready = []
            for j in succ_i.tolist():
                indeg[j] -= 1
                if indeg[j] == 0:
                    ready.append(j)
        for j in ready:  # pushed in the same order either way
            heapq.heappush(free.setdefault(kl[j], []), j)
    return np.array(order, np.int64)


def sample_frames(n_frames: int) -> np.ndarray:
    """About SAMPLE_FRAMES evenly spread frames (all of them for short animations)."""
    return np.unique(np.linspace(0, n_frames - 1, min(n_frames, SAMPLE_FRAMES)).round().astype(np.int64))


def _overlap(a: np.ndarray, b: np.ndarray, margin: float) -> np.ndarray:
    """Separating-axis test of triangles a, b (..., 3, 2): True where their interiors overlap by > margin."""
    out = np.ones(a.shape[:-2], bool)
    for tri in (a, b):
        for e in range(3):
            edge = tri[..., (e + 1) % 3, :] - tri[..., e, :]
            axis = np.stack([-edge[..., 1], edge[..., 0]], axis=-1)
            axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
            pa = np.einsum("...vc,...c->...v", a, axis)
            pb = np.einsum("...vc,...c->...v", b, axis)
            gap = np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))
            out &= gap > margin
    return out


def _bary(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of points p (..., 2) in triangles tri (..., 3, 2)."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[..., 0] * v1[..., 1] - v1[..., 0] * v0[..., 1]
    den = np.where(np.abs(den) > 1e-12, den, 1e-12)
    u = (v2[..., 0] * v1[..., 1] - v1[..., 0] * v2[..., 1]) / den
    v = (v0[..., 0] * v2[..., 1] - v2[..., 0] * v0[..., 1]) / den
    return np.stack([1 - u - v, u, v], axis=-1)


def _nearer(a: np.ndarray, za: np.ndarray, b: np.ndarray, zb: np.ndarray) -> np.ndarray:
    """Whether triangle a is nearer than b where they overlap: both depth planes compared at the probe points
    (vertices, centroids, centroid midpoint) that lie inside both, else at the centroid midpoint."""
    probes = np.concatenate([a, b, a.mean(axis=-2, keepdims=True), b.mean(axis=-2, keepdims=True),
                             ((a.mean(axis=-2) + b.mean(axis=-2)) / 2)[..., None, :]], axis=-2)  # (..., 9, 2)
    ba = _bary(a[..., None, :, :], probes)
    bb = _bary(b[..., None, :, :], probes)
    inside = (ba > -1e-6).all(-1) & (bb > -1e-6).all(-1)
    diff = (ba * za[..., None, :]).sum(-1) - (bb * zb[..., None, :]).sum(-1)  # (..., 9)
    mean_inside = np.where(inside, diff, 0).sum(-1) / np.maximum(inside.sum(-1), 1)
    return np.where(inside.any(-1), mean_inside, diff[..., -1]) < 0


def front_of(sheet: Sheet, tris: np.ndarray, pairs: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For pairs (M, 2) at frames (S,): interiors overlap with both visible (S, M), and first is nearer (S, M)."""
    fr = np.asarray(frames)
    xy = np.take(sheet.xy[fr], sheet.faces[tris], axis=1)
    z = np.take(sheet.depth[fr], sheet.faces[tris], axis=1)
    vis = np.take(sheet.visible[fr], tris, axis=1)
    m = len(pairs)
    overlap = np.zeros((len(fr), m), bool)
    first_nearer = np.zeros((len(fr), m), bool)
    for s in range(0, m, CHUNK):  # chunks bound memory
        pa, pb = pairs[s:s + CHUNK, 0], pairs[s:s + CHUNK, 1]
        a, b = xy[:, pa].astype(np.float64), xy[:, pb].astype(np.float64)
        overlap[:, s:s + CHUNK] = vis[:, pa] & vis[:, pb] & _overlap(a, b, OVERLAP_MARGIN_PX)
        first_nearer[:, s:s + CHUNK] = _nearer(a, z[:, pa].astype(np.float64), b, z[:, pb].astype(np.float64))
    return overlap, first_nearer


def draw_list(sheet: Sheet, layers: bool = False) -> DrawList:
    """Paths back to front: the sheet's painter's order (neutral frame), each shown where visible; with layers,
    the experimental layer copies (``layered``), off by default because they measured worse (module docstring)."""
    if layers:
        return layered(sheet)
    tris = np.asarray(sheet.order, np.int32)
    return DrawList(tris, np.take(sheet.visible, tris, axis=1))


def layered(sheet: Sheet) -> DrawList:
    """Experimental: the fixed order plus layer copies of triangles that must cover later-drawn ones."""
    tris = np.asarray(sheet.order, np.int32)
    active = np.take(sheet.visible, tris, axis=1)
    if len(tris) < 2:
        return DrawList(tris, active)
    samples = sample_frames(sheet.n_frames)
    pairs = overlapping_pairs(sheet, tris, samples)
    if not len(pairs):
        return DrawList(tris, active)
    overlap, first_nearer = front_of(sheet, tris, pairs, samples)
    # Positions: pairs[:, 0] is drawn first, so a conflict is "the first is nearer" where they overlap.
    # Pairs whose order flips between samples are checked at every frame.
    suspect = (overlap & first_nearer).any(axis=0) | (first_nearer.any(axis=0) & ~first_nearer.all(axis=0))
    pairs = pairs[suspect]
    overlap, first_nearer = front_of(sheet, tris, pairs, np.arange(sheet.n_frames))
    conflict = overlap & first_nearer
    n_conflicts = int(conflict.sum())
    has = conflict.any(axis=0)
    if not n_conflicts:
        return DrawList(tris, active)
    lo, hi = pairs[has, 0], pairs[has, 1]
    conflict = conflict[:, has]
    # Each triangle that must cover a later one: one copy after the last such triangle, shown at those frames.
    movers = np.unique(lo)
    after = np.full(len(tris), -1)
    np.maximum.at(after, lo, hi)
    up = np.zeros((sheet.n_frames, len(tris)), bool)
    for j in range(len(lo)):
        up[:, lo[j]] |= conflict[:, j]
    keys = np.concatenate([np.arange(len(tris), dtype=np.float64), after[movers] + 0.5])
    all_tris = np.concatenate([tris, tris[movers]])
    all_active = np.concatenate([active & ~up, (active & up)[:, movers]], axis=1)
    order = np.lexsort((np.arange(len(keys)), keys))
    out = DrawList(all_tris[order].astype(np.int32), all_active[:, order], n_conflicts, 0)
    return out._replace(residual=residual_conflicts(sheet, out, samples))


def residual_conflicts(sheet: Sheet, dl: DrawList, frames: np.ndarray | None = None) -> int:
    """(pair, frame) conflicts of a draw list at frames (default: all): overlapping shown paths where the
    earlier-drawn one is nearer."""
    frames = np.arange(sheet.n_frames) if frames is None else frames
    pairs = overlapping_pairs(sheet, dl.triangles, frames, dl.active)
    pairs = pairs[dl.triangles[pairs[:, 0]] != dl.triangles[pairs[:, 1]]]
    if not len(pairs):
        return 0
    overlap, first_nearer = front_of(sheet, dl.triangles, pairs, frames)
    both = dl.active[frames][:, pairs[:, 0]] & dl.active[frames][:, pairs[:, 1]]
    return int((overlap & first_nearer & both).sum())
