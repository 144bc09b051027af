"""The flat animation's plan: every number the flat writers (svg_anim, lottie) spell, decided once.

``plan`` turns a Sheet and the options into a FlatPlan: the paths (one drawn triangle each, back to front after
order.draw_list, never-shown ones dropped), their seam strokes (seams.py: corner order, open or closed, stroked
or not), the rigid groups (groups.plan: runs of paths under a band's transform, local tracks), the shared animated
palette (palette.py) or each path's own held colour steps (colours.color_steps), the merged elements
(merge.plan: paths of one colour in one group drawn as one element of subpaths), and the keys: each path's
free knots with its hidden frames collapsed (collapse.Timeline), and each merged element's joint keys
(``merged_keys``). A writer only spells these; what text costs reaches the plan through groups.Costs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from converter import heap
from converter.encode import collapse, freeknots, groups, merge, seams
from converter.encode import keys as keyframes
from converter.encode import palette as shared_colours
from converter.encode.budget import ErrorBudget, viewbox_scale
from converter.encode.colours import color_error, color_steps
from converter.encode.order import draw_list
from converter.encode.tracks import Tracks
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, no_progress, span
from converter.sheet import Sheet

# Stroke of the fill colour over interior edges (seams.py): hides the anti-aliasing seams between neighbours. One
# side strokes a shared edge, so it is wider than the 0.5 px both sides drew when every edge was stroked: the egg
# of tests/writers/test_seams.py shows less page through its seams than then, and outlines do not grow.
STROKE_PX = 0.6
STATIC_LEVELS = 255.0  # a colour tolerance this wide keeps every colour static: no animated palette
SHARED_SET_SIZE = 8  # most triangles in one path of one shared colour by default: larger sets save few elements


class Strokes:
    """The seam strokes of a writer's paths (seams.py), looked up by triangle id: each triangle is drawn by one
    path (layer copies are never left open), so its corner order, 'z' and stroke follow it through every
    reordering of the paths."""

    def __init__(self, faces: np.ndarray, tris: np.ndarray, skip: np.ndarray, single: np.ndarray) -> None:
        n = len(faces)
        self.faces = np.array(faces, np.int32)
        self.start_of = np.zeros((2, n), np.int64)  # as laid out, and with a stroke (at most one edge out)
        self.closed_of = np.ones((2, n), bool)
        self.bare_of = np.zeros(n, bool)
        for k, s in enumerate((seams.layout(skip), seams.layout(single))):
            self.start_of[k, tris], self.closed_of[k, tris] = s.start, s.closed
            if k == 0:
                self.bare_of[tris] = ~s.stroked
        rows = np.take_along_axis(self.faces[tris], (self.start_of[0, tris, None] + np.arange(3)) % 3, axis=1)
        self.faces[tris] = rows  # each path's corners from the one written first: its skipped edge closes it

    def closed(self, tris: np.ndarray) -> np.ndarray:
        """Bool per path of triangles tris: its d ends with 'z'."""
        return self.closed_of[0, tris]

    def bare(self, tris: np.ndarray) -> np.ndarray:
        """Bool per path of triangles tris: it has no stroke."""
        return self.bare_of[tris]

    def stroke(self, tris: np.ndarray) -> np.ndarray:
        """Give the unstroked of triangles tris a stroke (a merged element has one for all its subpaths): returns
        per triangle the turn (0-2) its corners take from the order laid out before."""
        tris = np.asarray(tris)
        turn = (self.start_of[1, tris] - self.start_of[0, tris]) % 3
        self.faces[tris] = np.take_along_axis(self.faces[tris], (turn[:, None] + np.arange(3)) % 3, axis=1)
        self.start_of[0, tris], self.closed_of[0, tris] = self.start_of[1, tris], self.closed_of[1, tris]
        self.bare_of[tris] = False
        return turn


def strokes(sheet: Sheet, tris: np.ndarray, active: np.ndarray, frames: slice = slice(None)) -> Strokes:
    """The seam strokes of paths drawing triangles tris where active (T, P) over the sheet's frames (a slice of
    them for a still)."""
    welded = seams.welded_ids(sheet.xy[frames], sheet.depth[frames])
    skip, single = seams.skips(welded[sheet.faces[tris]], active, sheet.xy[frames], sheet.faces[tris], STROKE_PX / 2)
    tris = np.asarray(tris)
    _, first, counts = np.unique(tris, return_index=True, return_counts=True)
    copies = np.isin(tris, tris[first[counts > 1]])  # layer copies: closed and stroked, as before
    skip[copies] = single[copies] = False
    return Strokes(sheet.faces, tris, skip, single)


class MergedBand(NamedTuple):
    """The joint keys of merged elements of similar size, keyed together (``merged_keys``)."""

    sets: np.ndarray  # int (Q,) the plan's merged sets (indices into FlatPlan.sets) in this band
    width: int  # subpaths per key row: the band's largest set (smaller ones repeat their last path)
    timeline: collapse.Timeline  # per set (path = its row in sets) its keys, values (K, width * 6) px as tracked


@dataclass
class FlatPlan:
    """What a flat writer spells (module docstring); track and timeline are handed over (set to None) by the
    writer once used: on a long capture they are the largest arrays."""

    mode: str  # 'bounded' (keys within the budget), 'raw' or 'chapter' (every frame, svg_anim's docstring)
    budget: ErrorBudget
    tris: np.ndarray  # int (P,) the triangle each path draws, in document order
    active: np.ndarray  # bool (T, P) the path shows at the frame
    strokes: Strokes  # seam strokes by triangle: corner order (strokes.faces), closed, bare
    rigid: groups.Plan | None  # rigid groups (runs of paths under a band's transform); its track/timeline moved out
    track: Tracks | None  # each path's corners per frame, px: local under a group, else screen
    timeline: collapse.Timeline | None  # each path's keys within its radius, hidden frames collapsed (bounded)
    joined: merge.Merge | None  # paths drawn as one element (starts), else None
    shared: shared_colours.Palette | None  # the animated palette the paths refer to (the default), else None
    steps: keyframes.Keys | None  # each path's own held colour steps (--exact, static colours), else None
    merged: list[MergedBand]  # the merged elements' joint keys (bounded)
    conflicts: int  # depth-order conflicts found and left (order.draw_list)
    residual: int

    @property
    def n_paths(self) -> int:
        """Paths (triangles as drawn, layer copies included)."""
        return len(self.tris)

    @property
    def starts(self) -> np.ndarray:
        """int (E + 1,) first path of each element, then P."""
        return np.arange(self.n_paths + 1) if self.joined is None else self.joined.starts

    @property
    def sets(self) -> list[tuple[int, int]]:
        """(first, one-past-last path) of each element of more than one path."""
        s = self.starts
        return [(a, b) for a, b in zip(s[:-1].tolist(), s[1:].tolist()) if b - a > 1]

    def radius(self) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Euclidean px left for keyframing and the bound an exactly checked fit may use (``radius``)."""
        return radius(self.budget, self.rigid)

    def colour_error(self, sheet: Sheet) -> np.ndarray:
        """8-bit levels between each shown frame's exact colour and what the plan plays there (its palette entry's
        held steps, or the path's own steps)."""
        columns = sheet.color_columns(self.tris)
        if self.shared is None:
            return color_error(sheet.face_rgb, self.active, self.steps, columns)
        return shared_colours.played_error(sheet.face_rgb, columns, self.active, self.shared)

    def gain(self) -> np.ndarray:
        """float64 (P,) local -> screen error gain of each path's group (1 without groups)."""
        return self.rigid.gain if self.rigid is not None else np.ones(self.n_paths)


class Still(NamedTuple):
    """One frame as static paths: what a flat writer spells for --frame (``still``)."""

    frame: int
    scale: int  # integer units per px (ErrorBudget's viewbox scale)
    tris: np.ndarray  # int (P,) triangles shown at the frame, back to front
    levels: np.ndarray  # int64 (P, 3) each one's exact colour at the frame, 8-bit levels
    corners: np.ndarray  # int64 (P, 6) its corners on the scale's grid, from the one its path starts at
    closed: np.ndarray  # bool (P,) the path is closed (else its one outline edge is left open)
    bare: np.ndarray  # bool (P,) the path has no seam stroke


def still(sheet: Sheet, options: ConversionOptions, frame: int) -> Still:
    """One frame of the sheet as static paths (exact colours, coordinates rounded to the tolerance's grid, this
    frame's own seam strokes); InputError for a frame outside the animation."""
    if not 0 <= frame < sheet.n_frames:
        raise InputError(f"frame {frame} is outside 0..{sheet.n_frames - 1}; choose one inside.")
    scale = viewbox_scale(options.tolerance)
    tris = sheet.order[sheet.visible[frame, sheet.order]]
    levels = np.clip(np.rint(sheet.face_rgb[frame, sheet.color_columns(tris)] * 255), 0, 255).astype(np.int64)
    st = strokes(sheet, tris, np.ones((1, len(tris)), bool), slice(frame, frame + 1))  # this frame's outline
    q = np.rint(sheet.xy[frame][st.faces[tris]].reshape(-1, 6).astype(np.float64) * scale).astype(np.int64)
    return Still(frame, scale, tris, levels, q, st.closed(tris), st.bare(tris))


def radius(budget: ErrorBudget, rigid: groups.Plan | None) -> tuple[float | np.ndarray, float | np.ndarray]:
    """Euclidean px left for keyframing and the bound an exactly checked fit may use, per path under a plan
    (local px, scaled down by the error gain of the path's group transform)."""
    if rigid is None:
        return budget.keys, budget.fit_bound
    return rigid.radius, budget.fit_bound / rigid.gain


def plan(sheet: Sheet, options: ConversionOptions, mode: str, costs: groups.Costs,
         progress: Progress = no_progress) -> FlatPlan:
    """The plan of the flat animation in mode ('bounded', 'raw' or 'chapter'); costs: the writer's text costs
    for the rigid groups; progress from the drawing order to the keys."""
    dl = draw_list(sheet, layers=options.depth_layers)
    tris, active = dl.triangles, dl.active
    shown = active.any(axis=0)  # a path never shown is dropped
    tris, active = tris[shown], np.compress(shown, active, axis=1)
    p = len(tris)
    budget = ErrorBudget.split(options.tolerance, max(sheet.camera.width, sheet.camera.height))
    sharing = mode == "bounded" and not options.exact and options.color_tolerance < STATIC_LEVELS and p > 0
    merging = mode == "bounded" and (sharing or (options.max_animations is not None and p > options.max_animations))
    st = strokes(sheet, tris, active)
    faces = st.faces  # each path's corners from the one its d starts at
    rigid = None
    keys_from = 0.0  # progress where the plain keys start, when they are worked out
    if mode == "bounded" and options.rigid and p:
        rigid = groups.plan(sheet.xy, faces, sheet.part_ids, sheet.neutral, tris, active, budget, costs,
                            progress=progress)
        heap.give_back()  # the plan's temporaries, before the text's
        if rigid.head is not None:  # else nothing pays for a group: the plain encoding, byte for byte
            tris, active, track = tris[rigid.order], np.take(active, rigid.order, axis=1), rigid.track
        else:  # the plan stopped before its refining: the plain keys take that part of the progress
            rigid = None
            keys_from = groups.PLAN_SHARES[1]
    if rigid is None:  # the Sheet's float32 vertices, read a block of paths at a time
        track = Tracks.screen(sheet.xy, faces[tris])
    joined = None
    shared = None
    if sharing:
        shared = shared_colours.build(sheet.face_rgb, sheet.color_columns(tris), active, options.color_tolerance)
    if merging:
        # A merged element strokes all its subpaths: a path left unstroked (more than one outline edge) stays alone,
        # else its stroke would grow the silhouette.
        entries = None if shared is None else np.where(st.bare(tris), -1, shared.entry)
        joined, tris, active, track, rigid = _merge(sheet, faces, tris, active, track, rigid, options, entries)
        if shared is not None:
            shared = shared._replace(entry=shared.entry[joined.order])
        track = _stroke_merged(st, joined, tris, track)
    fp = FlatPlan(mode, budget, tris, active, st, rigid, track, None, joined, shared, None, [], dl.conflicts,
                  dl.residual)
    if mode != "bounded":
        return fp
    fp.timeline = _timeline(track, active, budget, rigid, span(progress, keys_from, 1.0))
    if rigid is not None:  # its keys live on only in the plan's timeline, its track in the plan's
        fp.rigid = rigid._replace(timeline=None, track=None)
    if fp.sets:
        fp.merged = merged_keys(track, active, np.broadcast_to(np.asarray(fp.radius()[0], np.float64), (p,)),
                                fp.sets)
    if shared is None:  # each path's own held steps within the colour tolerance
        columns = sheet.color_columns(tris)
        fp.steps = color_steps(sheet.face_rgb, active, options.color_tolerance, columns)  # as stored: no copy
        inside = merged_paths(fp.sets)
        if len(inside):  # a merged path's one static colour (its code's)
            fp.steps.mask[:, inside] = False
            fp.steps.mask[0, inside] = True
            fp.steps.values[0, inside] = joined.levels[inside]
    return fp


def merged_paths(sets: list[tuple[int, int]]) -> np.ndarray:
    """int: every path inside an element of more than one path."""
    return np.concatenate([np.arange(a, b) for a, b in sets]) if sets else np.zeros(0, np.int64)


def _merge(sheet: Sheet, faces: np.ndarray, tris: np.ndarray, active: np.ndarray, track: Tracks,
           rigid: groups.Plan | None, options: ConversionOptions, entries: np.ndarray | None = None):
    """converter.encode.merge's sets for the paths (triangles tris of faces; by palette entry where entries),
    and the paths, their tracks and the rigid plan in its order."""
    segment = np.zeros(len(tris), np.int64)
    if rigid is not None:  # a set never crosses the edge of a group
        edge = np.zeros(len(tris) + 1, np.int64)
        edge[rigid.groups.ravel()] = 1
        segment = np.cumsum(edge[:-1])
    joined = merge.plan(segment, None if entries is not None else sheet.face_colors(tris), active,
                        options.color_tolerance, np.take(sheet.xy, faces[tris], axis=1),
                        options.max_animations or 0, entries,
                        SHARED_SET_SIZE if entries is not None and options.max_animations is None else None)
    o = joined.order
    if rigid is not None:
        rigid = rigid._replace(track=rigid.track.reorder(o), radius=rigid.radius[o], band=rigid.band[o],
                               gain=rigid.gain[o], timeline=collapse.take_paths(rigid.timeline, o))
        track = rigid.track
    else:
        track = track.reorder(o)
    return joined, tris[o], np.take(active, o, axis=1), track, rigid


def _stroke_merged(st: Strokes, joined: merge.Merge, tris: np.ndarray, track: Tracks) -> Tracks:
    """An element of several subpaths has one stroke: its unstroked paths (st) get one (their corners turned so
    the one edge they leave out closes them), in track as well (the merged keys are worked out from it)."""
    counts = np.diff(joined.starts)
    inside = np.flatnonzero(np.repeat(counts > 1, counts))
    fix = inside[st.bare(tris[inside])]
    if not len(fix):
        return track
    turn = st.stroke(tris[fix])
    corners = np.array(track.corners)
    corners[fix] = np.take_along_axis(corners[fix], (turn[:, None] + np.arange(3)) % 3, axis=1)
    return Tracks(track.verts, corners)


def _timeline(track: Tracks, active: np.ndarray, budget: ErrorBudget,
              rigid: groups.Plan | None, progress: Progress = no_progress) -> collapse.Timeline:
    """The paths' keys within the budget, hidden frames collapsed (collapse.py): the rigid plan's, which it worked
    out to decide its groups, else free knots now, a block of paths at a time."""
    if rigid is not None:
        return rigid.timeline
    r = np.broadcast_to(np.asarray(radius(budget, rigid)[0], np.float64), (track.shape[1],))
    return collapse.fold_blocks(active, lambda a, b: freeknots.point_keys(track.take(slice(a, b)), active[:, a:b],
                                                                          r[a:b]),
                                freeknots.block_tracks(active.shape[0]), progress)


def merged_keys(track: Tracks, active: np.ndarray, radius: np.ndarray,
                sets: list[tuple[int, int]]) -> list[MergedBand]:
    """Per merged set (first, one-past-last path) its joint keys: every point keyed together (free knots within
    the set's tightest radius wherever any of its paths shows), each path collapsed where it hides; a path's
    values at the keys the others add lie on its own interpolant, so every shown frame keeps the bound. Sets are
    keyed in bands of sizes (2, 3-4, 5-8, ...), each padded to its largest: one width for all wasted ten times
    the work and memory on a few large sets among many small."""
    band = np.ceil(np.log2([b - a for a, b in sets])).astype(np.int64)
    return [merged_band(track, active, radius, [sets[k] for k in ks.tolist()], ks)
            for ks in (np.flatnonzero(band == w) for w in np.unique(band).tolist())]


def merged_band(track: Tracks, active: np.ndarray, radius: np.ndarray, sets: list[tuple[int, int]],
                index: np.ndarray | None = None) -> MergedBand:
    """merged_keys of sets keyed together, each padded to the largest (its last path repeated: the same bound
    twice, no other key); index: the sets' numbers in the plan (default 0..Q-1)."""
    t = active.shape[0]
    width = max(b - a for a, b in sets)
    idx = np.array([[min(a + i, b - 1) for i in range(width)] for a, b in sets], np.int64)  # (Q, M) padded
    q = len(sets)
    joint_track = track.take(idx.ravel()).reshape(t, q, width * 6)
    keys = freeknots.point_keys(joint_track, np.take(active, idx, axis=1).any(axis=2),
                                 radius[idx].min(axis=1))  # the tightest bound of the set's paths
    members = np.concatenate([np.arange(a, b) for a, b in sets])
    set_of = np.repeat(np.arange(q), [b - a for a, b in sets])
    slot = members - np.repeat([a for a, _ in sets], [b - a for a, b in sets])
    vals = np.take(keys.values.reshape(t + 1, q * width, 6), set_of * width + slot, axis=1)
    mk = keyframes.Keys(np.take(keys.mask, set_of, axis=1), vals, keys.first_active[set_of])
    tl = collapse.fold(mk, np.take(active, members, axis=1))
    bounds = np.searchsorted(tl.path, np.arange(len(members) + 1))
    paths, halves, values, coll, snaps = [], [], [], [], []
    first = 0
    for k, (a, b) in enumerate(sets):
        n = b - a
        lo, hi = bounds[first], bounds[first + n]
        h = np.unique(tl.half[lo:hi])
        v = np.empty((len(h), width, 6))
        for i in range(n):  # each path on its own interpolant at every key of the set
            s0, s1 = bounds[first + i], bounds[first + i + 1]
            for c in range(6):
                v[:, i, c] = np.interp(h, tl.half[s0:s1], tl.values[s0:s1, c])
        v[:, n:] = v[:, n - 1:n]
        pts = v.reshape(len(h), width, 3, 2)
        point = (pts == pts[:, :, :1]).all(axis=(2, 3))  # (K, M) the path is collapsed at the key
        s = collapse.snaps(point, np.ones((len(h) - 1, 1), bool))
        worst = np.where((s == -2).any(axis=1) | ((s == -1).any(axis=1) & (s == 1).any(axis=1)), -2,
                         np.where((s == -1).any(axis=1), -1, np.where((s == 1).any(axis=1), 1, 0)))
        paths.append(np.full(len(h), k))
        halves.append(h)
        values.append(v.reshape(len(h), width * 6))
        coll.append(point.all(axis=1))
        snaps.append(worst)
        first += n
    whole = collapse.Timeline(np.concatenate(paths), np.concatenate(halves), np.concatenate(values),
                              np.concatenate(coll), np.concatenate(snaps).astype(np.int8))
    return MergedBand(np.arange(q) if index is None else np.asarray(index, np.int64), width, whole)
