"""Error-bounded keyframe reduction: per track, the few keys whose linear interpolation stays within a bound.

A track is a vector of D numbers per frame (a triangle's 3 vertices: D = 6). Constraints apply only at the
frames where the track is *active* (its triangle is visible); elsewhere interpolation may wander freely, which
is the chapter's "drop coordinates while hidden" generalised.

The reduction is a greedy "feasible velocity cone" (a box here: one interval per coordinate): from the current
start key (time s, value p), a straight segment to a later key at frame e passes within ``eps`` of every active
frame k in between iff its velocity lies in the intersection of the intervals
``[(x_k - p - eps) / (k - s), (x_k - p + eps) / (k - s)]``. Each frame updates the box in O(D); when the next
active frame cannot be reached inside the box, the previous active frame becomes a key. The loop is compiled
(numba), one track at a time: the frames of a track are sequential, and a loop over frames vectorised over
tracks cost a Python iteration per frame even for the one or two tracks ``freeknots`` hands back.

The first key sits at time 0 holding the value of the first active frame; the last key sits at time T (SMIL's
keyTimes end at 1) and its value is free: any velocity in the final box extrapolates to a valid end, and zero
velocity is preferred, so a track that never moves beyond ``eps`` comes out as two equal keys (static).

Keys on sampled values are what the transform stacks and the exact (``--raw``) encoding need. Paths' vertices
and colours use ``converter.encode.freeknots`` instead, whose key values are free within the bound (fewer keys)
and which falls back on ``reduce`` here for the few tracks its compiled pass rejects.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from scipy import sparse
from scipy.linalg import solveh_banded

from converter.encode import parallel


class Keys(NamedTuple):
    """Kept keyframes of N tracks over T frames: key mask over frames 0..T and the key values."""

    mask: np.ndarray  # bool (T + 1, N): frame k (k = T is the loop end) is a key of track n
    values: np.ndarray  # float (T + 1, N, D): value at each key (undefined where not a key); float32 from point_keys
    first_active: np.ndarray  # int (N,): first active frame, -1 when the track is never active


class Packed(NamedTuple):
    """Keys with only the key values stored: a few per track where Keys holds T + 1 (the rigid plan keeps every
    path's keys while it decides its groups, ~50 of 336 frames on a capture)."""

    mask: np.ndarray  # bool (T + 1, N) as Keys.mask
    values: np.ndarray  # (K, D) the values at the keys, track by track, each track's by frame
    first_active: np.ndarray  # int (N,) as Keys.first_active
    start: np.ndarray  # int (N + 1,) where each track's values begin, then K

    def part(self, a: int, b: int) -> Packed:
        """Tracks a..b-1."""
        s = self.start[a:b + 1]
        return Packed(self.mask[:, a:b], self.values[s[0]:s[-1]], self.first_active[a:b], s - s[0])

    def unpack(self, a: int, b: int) -> Keys:
        """Dense Keys of tracks a..b-1 (values zero where not a key)."""
        sub = self.mask[:, a:b].copy()
        values = np.zeros((sub.shape[0], sub.shape[1], self.values.shape[1]), self.values.dtype)
        _move_keys(sub, values, self.values, self.start[a:b + 1], False)
        return Keys(sub, values, self.first_active[a:b])


def pack(keys: Keys) -> Packed:
    """keys with only their key values kept."""
    start = np.zeros(keys.mask.shape[1] + 1, np.int64)
    np.cumsum(np.count_nonzero(keys.mask, axis=0), out=start[1:])
    values = np.empty((int(start[-1]), keys.values.shape[2]), keys.values.dtype)
    _move_keys(keys.mask, keys.values, values, start, True)
    return Packed(keys.mask, values, keys.first_active, start)


@numba.njit(cache=True, nogil=True)
def _move_keys(mask, dense, packed, start, to_packed) -> None:
    """Key values between dense (T + 1, N, D), where mask, and packed (K, D), track by track from start (N + 1,),
    each track's by frame: in one pass over the frames (np.nonzero of the transposed mask and a fancy-indexed
    gather made several passes a block)."""
    at = start[:-1].copy()
    for k in range(mask.shape[0]):
        for j in range(mask.shape[1]):
            if mask[k, j]:
                for c in range(dense.shape[2]):
                    if to_packed:
                        packed[at[j], c] = dense[k, j, c]
                    else:
                        dense[k, j, c] = packed[at[j], c]
                at[j] += 1


def join(parts: list[Packed]) -> Packed:
    """Packed keys of consecutive tracks, one after another."""
    ends = np.cumsum([0] + [p.start[-1] for p in parts])
    return Packed(np.concatenate([p.mask for p in parts], axis=1), np.concatenate([p.values for p in parts]),
                  np.concatenate([p.first_active for p in parts]),
                  np.concatenate([[0]] + [p.start[1:] + e for p, e in zip(parts, ends[:-1])]).astype(np.int64))


def replace(base: Packed, cols: np.ndarray, new: Packed) -> Packed:
    """base with its tracks cols (ascending) replaced by new's tracks, in order."""
    counts = np.diff(base.start)
    counts[cols] = np.diff(new.start)
    start = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    from_new = np.zeros(len(counts), bool)
    from_new[cols] = True
    values = np.empty((int(start[-1]),) + base.values.shape[1:], base.values.dtype)
    values[np.repeat(from_new, counts)] = new.values
    values[np.repeat(~from_new, counts)] = base.values[np.repeat(~from_new, np.diff(base.start))]
    mask = base.mask.copy()
    mask[:, cols] = new.mask
    return Packed(mask, values, base.first_active, start)


def emptied(base: Packed, cols: np.ndarray) -> Packed:
    """base with its tracks cols (ascending) holding no keys (base itself when there are none)."""
    if not len(cols):
        return base
    empty = Packed(np.zeros((base.mask.shape[0], len(cols)), bool), base.values[:0], base.first_active[cols],
                   np.zeros(len(cols) + 1, np.int64))
    return replace(base, cols, empty)


def reduce(x: np.ndarray, active: np.ndarray, eps: float | np.ndarray) -> Keys:
    """Greedy keys on sampled values for tracks x (T, N, D), within eps per coordinate where active."""
    x = np.ascontiguousarray(x, np.float64)
    t, n, d = x.shape
    active = np.ascontiguousarray(active, bool)
    eps = np.require(np.broadcast_to(np.asarray(eps, np.float64), (n,)), None, ["C", "W"])  # one kernel signature
    mask = np.zeros((t + 1, n), bool)
    values = np.zeros((t + 1, n, d))
    first = np.full(n, -1, np.int64)
    if n and t:
        parallel.threaded(_reduce, n, x, active, eps, mask, values, first)
    return Keys(mask, values, first)


@numba.njit(cache=True, nogil=True)
def _reduce(x, active, eps, mask, values, first, j0, j1):
    """reduce() of tracks j0..j1-1 into mask, values and first (the module docstring's box greedy, track by
    track: the same arithmetic, so the same keys, as the loop over frames vectorised over tracks it replaced)."""
    t, _, d = x.shape
    lo = np.empty(d)
    hi = np.empty(d)
    for j in range(j0, j1):
        f = -1
        for k in range(t):
            if active[k, j]:
                f = k
                break
        first[j] = f
        sk = max(f, 0)  # the start key's value is x[sk]: the first active frame's, then each cut's
        s = 0  # the start key's time
        mask[0, j] = f >= 0
        for c in range(d):
            values[0, j, c] = x[sk, j, c]
            lo[c], hi[c] = -np.inf, np.inf
        last = 0 if f == 0 else -1  # latest active frame after the start (always a feasible end)
        for k in range(1, t):
            if not active[k, j]:
                continue
            inv = 1.0 / (k - s)
            reachable = True
            for c in range(d):
                v = (x[k, j, c] - x[sk, j, c]) * inv
                if not (v >= lo[c] and v <= hi[c]):
                    reachable = False
            if not reachable and last > s:  # the previous active frame becomes a key and the new start
                mask[last, j] = True
                for c in range(d):
                    values[last, j, c] = x[last, j, c]
                    lo[c], hi[c] = -np.inf, np.inf
                s = sk = last
                inv = 1.0 / (k - s)
            for c in range(d):
                rel = x[k, j, c] - x[sk, j, c]
                new_lo, new_hi = (rel - eps[j]) * inv, (rel + eps[j]) * inv
                if new_lo > lo[c] or new_lo != new_lo:  # np.maximum / np.minimum, NaN included
                    lo[c] = new_lo
                if new_hi < hi[c] or new_hi != new_hi:
                    hi[c] = new_hi
            last = k
        # Loop end: free value on the last segment. Zero velocity when the box allows it, else the velocity to
        # the last active frame, which is always inside the box (and consistent across coordinates).
        zero_ok = True
        for c in range(d):
            if not (lo[c] <= 0 and hi[c] >= 0):
                zero_ok = False
        has = last > s
        span = last - s if has else 1
        mask[t, j] = f >= 0
        for c in range(d):
            vel = 0.0 if zero_ok or not has else (x[max(last, 0), j, c] - x[sk, j, c]) / span
            values[t, j, c] = x[sk, j, c] + (t - s) * vel


def interpolate(keys: Keys, frames: np.ndarray | None = None) -> np.ndarray:
    """Linear interpolation of the keys at integer frames (default 0..T-1): (len(frames), N, D)."""
    mask, values = keys.mask, keys.values
    t1, n, d = values.shape
    frames = np.arange(t1 - 1) if frames is None else np.asarray(frames)
    out = np.zeros((len(frames), n, d))
    for j in range(n):  # reference implementation for tests; the verifier evaluates the SVG itself
        kt = np.flatnonzero(mask[:, j])
        if len(kt) == 0:
            continue
        for c in range(d):
            out[:, j, c] = np.interp(frames, kt, values[kt, j, c])
    return out


def fewest(a: Keys, b: Keys) -> Keys:
    """Per track the keys of a or b, whichever has fewer (a on ties)."""
    win = b.mask.sum(axis=0) < a.mask.sum(axis=0)
    return Keys(np.where(win, b.mask, a.mask), np.where(win[:, None], b.values, a.values), a.first_active)


def _hat(n_frames: int, n_keys: int):
    """Sparse (T, n) matrix of linear interpolation from n evenly spaced keys over [0, T] to frames 0..T-1."""
    h = n_frames / (n_keys - 1)
    k = np.arange(n_frames)
    i = np.minimum(np.floor(k / h).astype(np.int64), n_keys - 2)
    f = k / h - i
    rows = np.concatenate([k, k])
    cols = np.concatenate([i, i + 1])
    return sparse.csr_matrix((np.concatenate([1 - f, f]), (rows, cols)), shape=(n_frames, n_keys))


def uniform_fit(x: np.ndarray, active: np.ndarray, n_keys: int, scale: float,
                radius: float | np.ndarray, pairs: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Evenly spaced keys (no keyTimes needed) for tracks x (T, N, D), least-squares fitted and rounded to the
    1/scale grid. Returns integer key values (n_keys, N, D) and whether every track stays within radius of x at
    every active frame, rounding included: Euclidean per 2D point when pairs, else per coordinate."""
    t, n, d = x.shape
    a = _hat(t, n_keys)
    lam = 1e-6  # keys without frames (none between the last frame and the loop end) hold the sampled value
    tau = np.minimum(np.arange(n_keys) * t / (n_keys - 1), t - 1)
    lo = np.floor(tau).astype(np.int64)
    hi = np.minimum(lo + 1, t - 1)
    w = (tau - lo)[:, None]
    flat = x.reshape(t, n * d)
    prior = flat[lo] * (1 - w) + flat[hi] * w
    ata = (a.T @ a).tocsr()
    band = np.zeros((2, n_keys))
    band[1] = ata.diagonal() + lam
    band[0, 1:] = ata.diagonal(1)
    v = solveh_banded(band, a.T @ flat + lam * prior)
    q = np.rint(v * scale)
    ok = np.empty(n, bool)
    _within(a.indptr, a.indices, a.data, np.ascontiguousarray(q / scale), np.ascontiguousarray(flat),
            np.ascontiguousarray(active, bool), np.broadcast_to(np.asarray(radius, np.float64), (n,)).copy(),
            d, pairs, ok)
    return q.reshape(n_keys, n, d).astype(np.int64), ok


@numba.njit(cache=True, nogil=True)
def _within(indptr, indices, data, keys, flat, active, radius, d, pairs, ok):
    """uniform_fit's check, track by track, stopping at its first frame out of bounds: ok[j] = at every active
    frame k the keys interpolated (row k of the CSR hat matrix times keys, as scipy sums it) are within radius[j]
    of flat[k] for each point (pairs: Euclidean per 2D point, else per coordinate). A NaN distance passes, as
    numpy's max and > let it. As numpy it was (T, N * D) float64 temporaries, much of the uniform keys' time."""
    t = flat.shape[0]
    step = 2 if pairs else 1
    for j in range(len(ok)):
        good = True
        for k in range(t):
            if not active[k, j]:
                continue
            worst = -np.inf
            nan = False
            for c in range(j * d, (j + 1) * d, step):
                y = 0.0
                for jj in range(indptr[k], indptr[k + 1]):
                    y += data[jj] * keys[indices[jj], c]
                dev = y - flat[k, c]
                if pairs:
                    y2 = 0.0
                    for jj in range(indptr[k], indptr[k + 1]):
                        y2 += data[jj] * keys[indices[jj], c + 1]
                    dy = y2 - flat[k, c + 1]
                    e = np.sqrt(dev * dev + dy * dy)
                else:
                    e = abs(dev)
                if e != e:
                    nan = True
                elif e > worst:
                    worst = e
            if not nan and worst > radius[j]:
                good = False
                break
        ok[j] = good
