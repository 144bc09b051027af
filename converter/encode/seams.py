"""Which triangle edges get the anti-seam stroke: interior edges only, so the silhouette does not grow.

Neighbouring triangles each anti-alias their shared edge, and the page shows through the seam between them; a
thin stroke of the fill colour over the edge hides it. Drawn on an outline edge, the same stroke fattens the
silhouette by half its width (with every edge stroked, the flat writer's 0.25 px rim held IoU against three.js
to 0.968 on MorphStressTest's bars and 0.972 on a thin-limbed robot). An edge is an outline edge at a frame where
no other drawn path shares it (welded vertices compared): a mesh boundary, or a neighbour that is back-facing,
culled or hidden that frame. Near the outline a stroke on an interior edge runs outside too, so an edge also
counts as outline where either side is a sliver narrower than the stroke's reach with its third corner on the
silhouette, or where it starts at a silhouette vertex and stays within NEAR_PX of the outline there (a thin
strip's diagonal); a seam left open there lies within the outline's own anti-aliasing.

An SVG path strokes every segment it draws but the implicit closing one, so per path one edge can be left out
(written last-to-first, the path open) or all of them (no stroke), and the choice is fixed for the whole
animation. ``skips`` makes it from each edge's frames as outline and as interior: a path leaves out the edges
that are ever outline (one: open there; two or three: unstroked), and wherever two paths that are interior
neighbours at some frame would both leave their shared edge out, the one whose edge is less often outline
strokes it after all. So every shared edge is stroked by one side at every frame where it is interior (no seam
opens), and what still grows the outline is an edge that is outline at some frames and, on the side that strokes
it, interior at others (MorphStressTest: 0.986 at worst; the robot, whose limbs turn: 0.983). ``stroke_off`` names
the frames where a path's stroke does that, for a writer to turn it off there (exact Gouraud, whose 1 px stroke
held the robot to 0.977: 0.985 with it), wherever the neighbours' strokes keep every interior edge covered.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

FRAME_BLOCK = 64  # frames whose (T, P, 3) edge states exist at once
BLOCK_CORNERS = 1 << 19  # at most this many corners' positions gathered at once (a few (b, P, 3, 2) float64)
NEAR_PX = 1.0  # an edge from a silhouette vertex that stays this near an outline edge there is left unstroked
MAX_ROUNDS = 8  # conflict-resolution rounds (each only adds strokes, so conflicts only go away)


class Seams(NamedTuple):
    """Per path: which edges the stroke leaves out, and the corner order and stroke that writes it."""

    skip: np.ndarray  # bool (P, 3): edge i (corner i to i+1) is not stroked
    start: np.ndarray  # int (P,): the corner written first (an open path's closing edge is its one skipped edge)
    closed: np.ndarray  # bool (P,): the path ends with 'z' (no edge or every edge skipped)
    stroked: np.ndarray  # bool (P,): the path has a stroke at all


def welded_ids(xy: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(V,) one id per group of vertices that coincide in every frame (xy (T, V, 2), depth (T, V)).

    Meshes split along UV, normal or part seams carry duplicate vertices; welded, their shared edges count as
    interior. Compared on the first frame and a random-weighted sum over all frames (one pass): vertices with the
    same bits in every frame have the same sums, others differ with probability 1."""
    t, v = depth.shape
    if not v:
        return np.zeros(0, np.int64)
    w = np.random.default_rng(0).random(t)
    key = np.empty((v, 6))
    key[:, 0:2] = xy[0]
    key[:, 2] = depth[0]
    key[:, 3:5] = np.tensordot(w, np.asarray(xy, np.float64), axes=(0, 0))
    key[:, 5] = w @ np.asarray(depth, np.float64)
    _, ids = np.unique(key, axis=0, return_inverse=True)
    return ids.reshape(-1)


def partners(corners: np.ndarray) -> np.ndarray:
    """(P, 3) the same edge in the other path sharing edge i (corner i to i+1) of each path, as 3 * path + edge
    (corners: welded vertex ids (P, 3)): -1 on a boundary edge, -2 where three or more paths share it."""
    p = len(corners)
    a = np.asarray(corners, np.int64)
    b = np.roll(a, -1, axis=1)
    n = int(a.max(initial=0)) + 1
    code = (np.minimum(a, b) * n + np.maximum(a, b)).ravel()
    order = np.argsort(code, kind="stable")
    _, first, counts = np.unique(code[order], return_index=True, return_counts=True)
    out = np.full(3 * p, -1, np.int64)
    two = first[counts == 2]
    out[order[two]] = order[two + 1]
    out[order[two + 1]] = order[two]
    out[order[np.repeat(counts, counts) > 2]] = -2
    return out.reshape(p, 3)


def heights(tri: np.ndarray) -> np.ndarray:
    """(..., 3) each triangle's height over edge i (corner i to i+1) of corners tri (..., 3, 2) px."""
    e = np.roll(tri, -1, axis=-2) - tri
    twice_area = np.abs(e[..., 0, 0] * e[..., 1, 1] - e[..., 0, 1] * e[..., 1, 0])
    return twice_area[..., None] / np.maximum(np.hypot(e[..., 0], e[..., 1]), 1e-12)


def edge_frames(pe: np.ndarray, active: np.ndarray, corners: np.ndarray | None = None, xy: np.ndarray | None = None,
                tri_ids: np.ndarray | None = None, reach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(outline (P, 3), interior (P, 3)): per edge the frames where its path is drawn and the edge counts as
    outline, and those where it is interior (never either on an edge shared by three or more). pe: partners();
    active (T, P): the path is drawn. An edge is interior where the other path is drawn too; given the welded
    corners (P, 3), xy (T, V, 2) px, the paths' vertex ids tri_ids (P, 3) and the stroke's half width reach,
    only where its stroke stays inside: not where either path is narrower than reach across it with its third
    corner on the silhouette (a sliver seen edge-on), nor where it starts at a silhouette vertex and lies within
    NEAR_PX of an outline edge there all along (a thin strip's diagonal: its stroke would run outside the
    silhouette for most of its length, and a seam left open there lies in the outline's own anti-aliasing)."""
    p = active.shape[1]
    outline = np.zeros((p, 3), np.int64)
    interior = np.zeros((p, 3), np.int64)
    for _, out, inside in edge_states(pe, active, corners, xy, tri_ids, reach):
        outline += out.sum(axis=0)
        interior += inside.sum(axis=0)
    return outline, interior


def edge_states(pe: np.ndarray, active: np.ndarray, corners: np.ndarray | None = None, xy: np.ndarray | None = None,
                tri_ids: np.ndarray | None = None, reach: float = 0.0) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Per block of frames (first frame a, outline (b, P, 3), interior (b, P, 3)): each edge's state at each
    frame, as edge_frames counts them (arguments as it takes them); a block at a time so memory stays small."""
    t, p = active.shape
    bound = pe == -1
    shared = pe >= 0
    other = np.where(shared, pe, 0).ravel()
    geometry = xy is not None and reach > 0
    step = FRAME_BLOCK if not geometry else max(1, min(FRAME_BLOCK, BLOCK_CORNERS // max(3 * p, 1)))
    for a in range(0, t, step):
        act = active[a:a + step]
        b = len(act)
        nb = np.take(act, other // 3, axis=1).reshape(b, p, 3) & shared  # the other path is drawn
        mine = act[..., None]
        inside = mine & nb
        if geometry:
            pts = np.take(np.asarray(xy[a:a + b], np.float32), tri_ids, axis=1).astype(np.float64)  # (b, P, 3, 2)
            ok = _stays_inside(mine & ~nb & (bound | shared), corners, pts, reach)
            inside &= ok & np.take(ok.reshape(b, 3 * p), other, axis=1).reshape(b, p, 3)
        yield a, mine & ~inside & (bound | shared), inside


def _stays_inside(out: np.ndarray, corners: np.ndarray, pts: np.ndarray, reach: float) -> np.ndarray:
    """(b, P, 3): a stroke reaching `reach` px either side of each edge stays inside the drawn paths on this
    path's side (edge_frames' rules), given the outline edges out (b, P, 3) and corner positions pts (b, P, 3, 2)."""
    b, p = out.shape[:2]
    n = int(corners.max(initial=0)) + 1
    e = np.roll(pts, -1, axis=2) - pts  # edge i: corner i to i+1
    length = np.maximum(np.hypot(e[..., 0], e[..., 1]), 1e-12)
    unit = e / length[..., None]
    # the silhouette's vertices, each with (up to) two outline directions through it
    k, j, i = np.nonzero(out)
    heads = [(corners[j, i], unit[k, j, i]), (corners[j, (i + 1) % 3], unit[k, j, i])]
    on = np.zeros((b, n), bool)
    dirs = np.zeros((2, b, n, 2))
    for v, d in heads:
        on[k, v] = True
        dirs[0, k, v] = d  # the last written wins here, the first in dirs[1]
    for v, d in reversed(heads):
        dirs[1, k[::-1], v[::-1]] = d[::-1]
    # a sliver: the corner opposite the edge on the silhouette, nearer the edge than reach
    twice_area = np.abs(e[..., 0, 0] * e[..., 1, 1] - e[..., 0, 1] * e[..., 1, 0])
    height = twice_area[..., None] / length
    frame = np.arange(b)[:, None, None]
    apex = np.roll(corners, -2, axis=1)[None]  # corner i+2, opposite edge i
    ok = ~(on[frame, apex] & (height < reach))
    # a strip's diagonal: from a silhouette vertex, its far end within NEAR_PX of an outline edge through it
    for end, far in ((corners, e), (np.roll(corners, -1, axis=1), -e)):
        v = np.broadcast_to(end[None], (b, p, 3))
        for d in dirs:
            dv = d[frame, v]  # (b, P, 3, 2)
            dist = np.abs(dv[..., 0] * far[..., 1] - dv[..., 1] * far[..., 0])
            ok &= ~(on[frame, v] & (dist < NEAR_PX) & (np.hypot(dv[..., 0], dv[..., 1]) > 0))
    return ok


def skips(corners: np.ndarray, active: np.ndarray, xy: np.ndarray | None = None, tri_ids: np.ndarray | None = None,
          reach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Bool (P, 3): edge i (corner i to i+1) of each path is not stroked (corners: welded vertex ids (P, 3);
    active (T, P): drawn at frame k; xy, tri_ids and reach (the stroke's half width) as edge_frames takes them),
    as the module docstring describes: outline edges left out where no seam opens; and the same with at most one
    edge left out a path (an unstroked one keeps out its most often outline edge only), for a path that must have
    a stroke."""
    p = len(corners)
    pe = partners(corners)
    outline, together = edge_frames(pe, active, corners, xy, tri_ids, reach)
    shared = pe >= 0
    back = np.where(shared, pe, 0)  # flat index of the same edge on the other side
    skip = outline > 0
    skip[skip.sum(axis=1) >= 2] = True  # two or three edges ever outline: no stroke (the others are neighbours')
    flat_outline = outline.ravel()
    for _ in range(MAX_ROUNDS):
        conflict = skip & shared & (together > 0) & skip.ravel()[back].reshape(p, 3)
        if not conflict.any():
            break
        # Of the two sides, the one whose edge is less often outline strokes it (ties: the lower flat index).
        mine, theirs = flat_outline, flat_outline[back.ravel()]
        lose = conflict.ravel() & ((mine < theirs) | ((mine == theirs) & (np.arange(3 * p) < back.ravel())))
        for f in np.flatnonzero(lose).tolist():
            j, i = divmod(f, 3)
            if skip[j].all():  # unstroked: keep out its most often outline edge but i, stroke the rest
                rest = np.where(np.arange(3) == i, -1, outline[j])
                keep = int(np.argmax(rest))
                skip[j] = False
                skip[j, keep] = outline[j, keep] > 0
            else:
                skip[j, i] = False
    single = skip.copy()  # removing skips opens no seam
    many = np.flatnonzero(skip.sum(axis=1) >= 2)
    single[many] = False
    single[many, np.argmax(outline[many], axis=1)] = True
    return skip, single


def layout(skip: np.ndarray) -> Seams:
    """The Seams of skipped edges (P, 3): one skipped edge is written last (the path starts after it, open),
    none or three keep the corner order and 'z'."""
    n = skip.sum(axis=1)
    start = np.where(n == 1, (np.argmax(skip, axis=1) + 1) % 3, 0)
    return Seams(skip, start, n != 1, n < 3)



def stroke_off(corners: np.ndarray, active: np.ndarray, skip: np.ndarray, xy: np.ndarray | None = None,
               tri_ids: np.ndarray | None = None, reach: float = 0.0) -> np.ndarray:
    """Bool (T, P): frames where a drawn path's stroke is better off, one of the edges it strokes (skip (P, 3)
    false, not every edge skipped) counting as outline then, and every other edge it strokes that is interior
    then stroked by the other side too (arguments as skips takes them), so no seam opens.

    skips fixes one layout for the whole animation, so an edge that is outline at some frames and interior at
    others is stroked at both; a writer that drops the path's stroke at these frames keeps the silhouette."""
    t, p = active.shape
    out = np.zeros((t, p), bool)
    pe = partners(corners)
    stroked = ~skip & ~skip.all(axis=1, keepdims=True)
    back = np.where(pe >= 0, pe, 0).ravel()
    for a, outline, inside in edge_states(pe, active, corners, xy, tri_ids, reach):
        b = len(outline)
        off = (outline & stroked).any(axis=2)
        while off.any():  # each round only turns strokes back on, so it ends
            theirs = np.take((stroked[None] & ~off[..., None]).reshape(b, 3 * p), back, axis=1).reshape(b, p, 3)
            needed = off & (inside & stroked & ~theirs).any(axis=2)
            if not needed.any():
                break
            off &= ~needed
        out[a:a + b] = off
    return out
