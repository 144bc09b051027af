"""Visibility folded into the geometry keys: a hidden triangle is a triangle collapsed to one point.

A path's keys (``keys.Keys``, frames 0..T) hold it within the bound at the frames where it is active and are
free elsewhere. ``fold`` makes them hide the path at every inactive frame with no other animation: each hidden
run [h0, h1] gets a collapsed key (all three vertices at one point) half a frame before h0 and half a frame
after h1 (at 0 and T where the run touches the loop's ends), and the visible frames next to the run get keys on
the original interpolant, so every visible frame plays what it played before. Between two collapsed keys every
interpolated value is collapsed too (the three vertices move together), so keys inside the run are dropped.
The triangle shrinks to its centroid within the half frame before it disappears and grows back within the
half frame before it shows; a player never evaluates a frame time on those half-frame segments.

Times are counted in half frames (0..2T). ``snap`` says how a writer may round each key's time: -1 only
earlier (a visible key right after a collapse), +1 only later (right before one), 0 either way; -2 marks a
visible key between two collapses, which must be placed exactly enough for both (its slope includes them).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from converter.arrays import lexsort_ints
from converter.encode.keys import Keys
from converter.options import Progress, no_progress

FOLD_CELLS = 1 << 19  # path-frames folded at a time


class Timeline(NamedTuple):
    """Keys of P paths in path-major order, times in half frames."""

    path: np.ndarray  # int (K,) path of each key, sorted
    half: np.ndarray  # int (K,) time in half frames, 0..2T, increasing within a path
    values: np.ndarray  # float (K, D) key values, in the keys' dtype (float32 from freeknots.point_keys)
    collapsed: np.ndarray  # bool (K,) the key is a collapse (hides the path)
    snap: np.ndarray  # int8 (K,): -1 round earlier only, +1 later only, 0 nearest, -2 exact (module docstring)


def runs(active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hidden runs of active (T, P): path, first and last hidden frame of each, path-major."""
    t, p = active.shape
    hidden = ~active.T  # (P, T)
    pad = np.zeros((p, 1), bool)
    edge = np.diff(np.concatenate([pad, hidden, pad], axis=1).astype(np.int8), axis=1)  # (P, T + 1)
    sp, sf = np.nonzero(edge == 1)
    _, ef = np.nonzero(edge == -1)
    return sp, sf, ef - 1


def interpolate_at(keys: Keys, path: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """The keys' linear interpolant of each path at each frame (both (N,)): (N, D)."""
    t1, p = keys.mask.shape
    pk, fk = np.nonzero(keys.mask.T)
    code = pk * t1 + fk
    vals = keys.values.transpose(1, 0, 2)[pk, fk]
    q = path * t1 + frame
    hi = np.minimum(np.searchsorted(code, q, side="left"), len(code) - 1)
    exact = code[hi] == q
    lo = np.where(exact, hi, hi - 1)
    span = np.maximum(fk[hi] - fk[lo], 1)
    f = np.where(exact, 0.0, (frame - fk[lo]) / span)[:, None]
    return vals[lo] + f * (vals[hi] - vals[lo])


def _point(v: np.ndarray) -> np.ndarray:
    """Triangle rows (N, 6+) collapsed to their centroid (extra columns kept)."""
    out = np.array(v)
    c = v[:, :6].reshape(len(v), 3, 2).mean(axis=1)
    out[:, :6] = np.tile(c, 3)
    return out


def fold(keys: Keys, active: np.ndarray) -> Timeline:
    """The keys with every inactive frame of each path hidden by collapsed keys (module docstring), a block of
    FOLD_CELLS path-frames at a time (paths are independent): its temporaries stay small on a long capture."""
    return fold_blocks(active, lambda a, b: Keys(keys.mask[:, a:b], keys.values[:, a:b], keys.first_active[a:b]))


def fold_blocks(active: np.ndarray, keys_of: Callable[[int, int], Keys], size: int | None = None,
                progress: Progress = no_progress) -> Timeline:
    """fold of the keys that keys_of(a, b) gives for paths a..b-1 (active (T, P)), asked for a block of size
    paths at a time (at most FOLD_CELLS path-frames): the keys of every path never exist at once.
    progress("keys", fraction of the paths done) before each block."""
    t, p = active.shape
    block = max(1, min(FOLD_CELLS // max(t, 1), size or p))
    if p <= block:
        progress("keys", 0.0)
        return _fold(keys_of(0, p), active)
    fields: list[list[np.ndarray]] = [[] for _ in Timeline._fields]
    for a in range(0, p, block):
        progress("keys", a / p)
        part = _fold(keys_of(a, min(a + block, p)), active[:, a:a + block])
        for out, x in zip(fields, part._replace(path=part.path + a)):
            out.append(x)
    joined = []
    while fields:  # one field at a time, its blocks let go as it is joined
        joined.append(np.concatenate(fields.pop(0)))
    return Timeline(*joined)


def take_paths(tl: Timeline, order: np.ndarray) -> Timeline:
    """The timeline of paths order (indices into tl's paths), renumbered 0..len(order)-1."""
    bounds = np.searchsorted(tl.path, np.arange(int(order.max(initial=-1)) + 2))
    counts = np.diff(bounds)[order]
    first = np.repeat(bounds[order] - np.cumsum(counts) + counts, counts)
    idx = first + np.arange(int(counts.sum()))
    return Timeline(np.repeat(np.arange(len(order)), counts), tl.half[idx], tl.values[idx], tl.collapsed[idx],
                    tl.snap[idx])


def _fold(keys: Keys, active: np.ndarray) -> Timeline:
    """fold of one block of paths."""
    t, p = active.shape
    pk, fk = np.nonzero(keys.mask.T)
    vals = keys.values.transpose(1, 0, 2)[pk, fk]
    # Original keys on visible frames (the loop end counts as frame T - 1's side).
    keep = active[np.minimum(fk, t - 1), pk]
    rp, r0, r1 = runs(active)
    before = r0 > 0  # visible frame r0 - 1 precedes the run
    after = r1 < t - 1  # visible frame r1 + 1 follows it
    vp = np.concatenate([rp[before], rp[after]])
    vf = np.concatenate([r0[before] - 1, r1[after] + 1])
    vv = (interpolate_at(keys, vp, vf) if len(vp) else np.zeros((0, vals.shape[1]))).astype(vals.dtype)
    # Collapsed keys: at the half frames round the run, or the loop's ends.
    c_start = np.where(before, 2 * r0 - 1, 0)
    c_end = np.where(after, 2 * r1 + 1, 2 * t)
    d = vals.shape[1]
    vb, va = np.zeros((len(rp), d), vals.dtype), np.zeros((len(rp), d), vals.dtype)  # visible before / after a run
    nb = int(before.sum())
    vb[before], va[after] = vv[:nb], vv[nb:]
    near = np.where(before[:, None], vb, va)  # what the collapse at the run's start shrinks from
    near_end = np.where(after[:, None], va, vb)  # what the one at its end grows into
    point_a, point_b = _point(near), _point(near_end)
    path = np.concatenate([pk[keep], vp, rp, rp])
    half = np.concatenate([2 * fk[keep], 2 * vf, c_start, c_end])
    values = np.concatenate([vals[keep], vv, point_a, point_b])
    collapsed = np.concatenate([np.zeros(int(keep.sum()) + len(vp), bool), np.ones(2 * len(rp), bool)])
    order = lexsort_ints((collapsed, half, path))
    path, half = path[order], half[order]
    dup = np.zeros(len(path), bool)
    dup[1:] = (path[1:] == path[:-1]) & (half[1:] == half[:-1])  # an edge frame that was already a key
    single = ~dup
    order = order[single]  # one gather of the values, sorted and deduplicated at once
    path, half, values, collapsed = path[single], half[single], values[order], collapsed[order]
    same = path[1:] == path[:-1]
    return Timeline(path, half, values, collapsed, snaps(collapsed, same))


def snaps(collapsed: np.ndarray, same: np.ndarray) -> np.ndarray:
    """Each key's snap (module docstring) from whether keys (K, ...) are collapses, along axis 0; same (K - 1,
    ...): keys i and i + 1 belong to one path."""
    prev = np.zeros_like(collapsed)
    prev[1:] = collapsed[:-1] & same
    after = np.zeros_like(collapsed)
    after[:-1] = collapsed[1:] & same
    snap = np.zeros(collapsed.shape, np.int8)
    snap[prev & ~collapsed] = -1
    snap[after & ~collapsed] = 1
    snap[prev & after & ~collapsed] = -2
    return snap
