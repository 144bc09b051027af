"""Shared animated colours: the paths' colour tracks clustered into a palette of animated colours.

Exact flat shading gives nearly every triangle its own colour track, and a colour animation is what players pay
most for (a restyle each frame per animated element). Neighbouring triangles of a face shade alike, so their
tracks cluster: a median cut over the tracks (every shown frame and channel a dimension) splits a cluster on the
frame and channel where its shades spread most, at the middle of that spread, until every cluster's shades lie
within ``spread_limit(tolerance)`` levels of each other at every frame and channel. One colour held in the middle of a
cluster's spread is then within the tolerance (rounding included) of every member at every shown frame, so each
palette entry animates once, as held steps (the fewest within the tolerance of every member: greedy over the
cluster's envelope, as ``steps.hold`` is over one path), and each path refers to its entry.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from converter.encode import parallel

BLOCK_CELLS = 1 << 24  # frame-path-channel cells of the level arrays read at once when finding envelopes


class Palette(NamedTuple):
    """Animated colours and which one each path plays."""

    entry: np.ndarray  # int64 (P,) palette entry of each path (-1: a path never shown)
    mask: np.ndarray  # bool (T + 1, K) a held step starts at this frame (frame 0 always, the loop end closes)
    values: np.ndarray  # uint8 (T + 1, K, 3) held levels from each step's first frame

    @property
    def size(self) -> int:
        """Number of palette entries K."""
        return int(self.mask.shape[1])

    def animated(self) -> np.ndarray:
        """Bool (K,): the entry changes colour during the animation."""
        first = self.values[0]
        return (self.mask[1:-1] & (self.values[1:-1] != first).any(axis=2)).any(axis=0)


def levels(rgb: np.ndarray, paths: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shown levels of rgb's columns paths, path-major (P, T, 3) so that a cluster's rows gather at once, as
    two uint8 arrays: hidden frames at 255 in the first (for minima) and at 0 in the second (for maxima), so
    either is one reduction."""
    t, p = active.shape
    lo = np.empty((p, t, 3), np.uint8)
    hi = np.empty((p, t, 3), np.uint8)
    step = max(1, BLOCK_CELLS // max(3 * t, 1))
    for a in range(0, p, step):
        sl = slice(a, a + step)
        v = np.clip(np.rint(np.take(rgb, paths[sl], axis=1) * np.float32(255)), 0, 255).astype(np.uint8)
        shown = active[:, sl, None]
        lo[sl] = np.where(shown, v, 255).transpose(1, 0, 2)
        hi[sl] = np.where(shown, v, 0).transpose(1, 0, 2)
    return lo, hi


def spread_limit(tolerance: float) -> int:
    """The widest spread of integer levels whose middle, rounded, lies within tolerance of every exact shade
    they round: ceil(spread / 2) for the middle's rounding and 0.5 for the levels'."""
    return max(0, 2 * int(np.floor(tolerance - 0.5 + 1e-9)))


def clusters(lo: np.ndarray, hi: np.ndarray, active: np.ndarray, tolerance: float) -> np.ndarray:
    """Cluster id (P,) of each path (lo, hi (P, T, 3) from ``levels``, shown where active (T, P); -1 for a path never
    shown): a median cut until each cluster's shown levels spread at most spread_limit(tolerance) at every frame and
    channel."""
    limit = spread_limit(tolerance)
    out = np.full(lo.shape[0], -1, np.int64)
    todo = [np.flatnonzero(active.any(axis=0))]
    # Each path's mean shown level per channel: its side of a cut at a frame where it is hidden.
    mean = (hi.sum(axis=1, dtype=np.float64) / np.maximum(active.sum(axis=0), 1)[:, None]).astype(np.float32)
    k = 0
    while todo:
        members = todo.pop()
        if not len(members):
            continue
        a = lo[members].min(axis=0).astype(np.int64)  # (T, 3)
        b = hi[members].max(axis=0).astype(np.int64)
        spread = np.where(b >= a, b - a, 0)
        worst = int(spread.argmax())
        if spread.flat[worst] <= limit or len(members) == 1:
            out[members] = k
            k += 1
            continue
        f, c = divmod(worst, 3)
        mid = (a[f, c] + b[f, c]) / 2
        at = np.where(active[f, members], hi[members, f, c].astype(np.float32), mean[members, c])
        low = at <= mid
        todo += [members[low], members[~low]]
    return out


def build(rgb: np.ndarray, paths: np.ndarray, active: np.ndarray, tolerance: float) -> Palette:
    """The animated palette of rgb's columns paths (rgb (T, N, 3) in 0..1 as the Sheet stores it) shown where
    active (T, P), every member within tolerance levels per channel of its entry's played colour at every frame
    it shows. Entries are numbered by first member in path order (deterministic)."""
    t, p = active.shape
    paths = np.asarray(paths, np.int64)
    lo, hi = levels(rgb, paths, active)
    cid = clusters(lo, hi, active, tolerance)
    # renumber by first member, so the palette follows the paths' order
    ids, first = np.unique(cid[cid >= 0], return_index=True)
    order = np.argsort(np.flatnonzero(cid >= 0)[first], kind="stable")
    remap = np.full(len(ids), -1, np.int64)
    remap[order] = np.arange(len(ids))
    entry = np.full(p, -1, np.int64)
    entry[cid >= 0] = remap[np.searchsorted(ids, cid[cid >= 0])]
    kk = len(ids)
    live = np.flatnonzero(entry >= 0)
    by = live[np.argsort(entry[live], kind="stable")]
    starts = np.searchsorted(entry[by], np.arange(kk))
    if kk:
        env_lo = np.ascontiguousarray(np.minimum.reduceat(lo[by], starts, axis=0).transpose(1, 0, 2))  # (T, K, 3)
        env_hi = np.ascontiguousarray(np.maximum.reduceat(hi[by], starts, axis=0).transpose(1, 0, 2))
        any_shown = np.logical_or.reduceat(np.take(active, by, axis=1), starts, axis=1)
    mask = np.zeros((t + 1, kk), bool)
    values = np.zeros((t + 1, kk, 3), np.uint8)
    if t and kk:
        parallel.threaded(_hold_range, kk, env_lo, env_hi, any_shown, float(tolerance), mask, values)
    return Palette(entry, mask, values)


def played_error(rgb: np.ndarray, paths: np.ndarray, active: np.ndarray, palette: Palette) -> np.ndarray:
    """Per shown (frame, path) the largest channel error in levels (float32) of the colour its entry plays
    against rgb's columns paths."""
    t, p = active.shape
    held = np.maximum.accumulate(np.where(palette.mask[:t], np.arange(t)[:, None], 0), axis=0)  # (T, K)
    out = []
    step = max(1, BLOCK_CELLS // max(3 * t, 1))
    for a in range(0, p, step):
        sl = slice(a, a + step)
        e = palette.entry[sl]
        ok = e >= 0
        if not ok.any():
            continue
        cols, e = paths[sl][ok], e[ok]
        exact = np.take(rgb, cols, axis=1).astype(np.float32) * np.float32(255)
        played = palette.values[held[:, e], e].astype(np.float32)  # (T, n, 3)
        err = np.abs(exact - played).max(axis=2)
        out.append(err[active[:, sl][:, ok]])
    return np.concatenate(out) if out else np.zeros(0, np.float32)


@numba.njit(cache=True, nogil=True)
def _hold_range(lo, hi, shown, tolerance, mask, values, first, stop):
    """Held steps of entries first..stop-1 over their envelopes lo..hi (T, K, 3) where shown (T, K): a step grows
    while the middle of its running range stays within tolerance (rounding included) of every level in it."""
    t = shown.shape[0]
    for j in range(first, stop):
        a = np.full(3, np.inf)
        b = np.full(3, -np.inf)
        start = 0
        for f in range(t + 1):
            if f < t:
                s = shown[f, j]
                spread = -np.inf
                for c in range(3):
                    spread = max(spread, max(b[c], np.float64(hi[f, j, c])) - min(a[c], np.float64(lo[f, j, c])))
                cut = s and np.ceil(spread / 2) + 0.5 > tolerance
            else:
                s, cut = False, True
            if cut:
                mask[start, j] = True
                for c in range(3):
                    mid = (a[c] + b[c]) / 2 if np.isfinite(a[c]) else 0.0
                    values[start, j, c] = np.uint8(min(max(np.rint(mid), 0.0), 255.0))
                start = f
                for c in range(3):
                    if f < t:
                        a[c], b[c] = np.float64(lo[f, j, c]), np.float64(hi[f, j, c])
            elif s:
                for c in range(3):
                    a[c], b[c] = min(a[c], np.float64(lo[f, j, c])), max(b[c], np.float64(hi[f, j, c]))
