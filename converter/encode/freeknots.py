"""Free-knot keyframe reduction: key values anywhere within the bound, so each straight segment runs longer.

``keys.reduce`` puts every key on a sampled value. Here a key's value is free: the segment from key j
(time s, value p) with velocity v passes within eps of active frame k iff ``|p + v (k - s) - x_k| <= eps``, a
strip in the (p, v) plane, one plane per coordinate. The greedy keeps, per coordinate, the convex polygon of
(p, v) that meets every active frame since s, with p restricted to the window of values key j can take given
the keys before it. When the next active frame would empty a polygon, the last active frame becomes key j+1 and
its window is the range of p + v (k - s) over the polygon. A backward pass then picks the values: the end key
with the smallest velocity (zero when the last segment allows it, so a track that never leaves eps is two equal
keys), and each earlier key in the middle of what its segment allows. Per coordinate this is the classic
window-propagating greedy for continuous piecewise-linear fitting under a max-norm bound. On captured motion
the file comes out markedly smaller than with keys on sampled values (bench_capture).

The loops do not vectorise (polygons grow and shrink per track), so they are compiled with numba.
``point_keys`` turns a Euclidean bound on 2D points into per-coordinate ones (a few rectangles inscribed in the
circle, the one needing fewest keys per track).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from converter.encode import keys, parallel
from converter.options import Progress, no_progress, span

BIG = 1e7  # bound of the unconstrained first value and of every velocity (px, px/frame)
MAX_VERTS = 40  # polygon capacity; a segment whose polygon would outgrow it is cut early (still valid)
ON_LINE = 1e-10  # relative distance below which a polygon vertex counts as on a cutting line
SHAPES_DEG = (45.0, 30.0, 60.0)  # per path, the rectangle in each vertex's tolerance circle that needs fewest keys
BLOCK_TRACKS = 1024  # at most this many tracks reduced together (bounds the per-shape dense keys)
BLOCK_CELLS = 1 << 18  # ... and at most about this many track-frames: a long capture takes fewer tracks a block
SLACK = 1e-8  # the bound holds to eps + SLACK (eps + |x| + 1); tracks the final check rejects get sampled keys


# The polygons live in one array, addressed by slot, and the helpers are inlined: numba reference-counts every
# array a function receives (atomic operations, contended between threads sharing x), which took much of the loop's
# time when each cut was a call on slices.
@numba.njit(cache=True, nogil=True, inline="always")
def _rect(dst, di, lo, hi) -> int:
    dst[di, 0, 0], dst[di, 0, 1] = lo, -BIG
    dst[di, 1, 0], dst[di, 1, 1] = hi, -BIG
    dst[di, 2, 0], dst[di, 2, 1] = hi, BIG
    dst[di, 3, 0], dst[di, 3, 1] = lo, BIG
    return 4


@numba.njit(cache=True, nogil=True, inline="always")
def _on_line(poly, pi, n, span, y) -> float:
    """A p with (p, v) in the polygon poly[pi, :n] and p + span v = y: the middle of that chord (nearest vertex if
    missed)."""
    lo, hi = np.inf, -np.inf
    best, best_g = 0.0, np.inf
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        gi = poly[pi, i, 0] + span * poly[pi, i, 1] - y
        gj = poly[pi, j, 0] + span * poly[pi, j, 1] - y
        if abs(gi) < best_g:
            best_g, best = abs(gi), poly[pi, i, 0] - gi  # shift p so the line is met exactly
        if gi == 0.0:
            lo, hi = min(lo, poly[pi, i, 0]), max(hi, poly[pi, i, 0])
        elif (gi < 0.0) != (gj < 0.0) and gj != 0.0:
            p = poly[pi, i, 0] + gi / (gi - gj) * (poly[pi, j, 0] - poly[pi, i, 0])
            lo, hi = min(lo, p), max(hi, p)
    return 0.5 * (lo + hi) if lo <= hi else best


@numba.njit(cache=True, nogil=True, inline="always")
def _slowest(poly, pi, n):
    """The (p, v) of the polygon poly[pi, :n] with the smallest |v|: on v = 0 (middle of that chord) when it
    crosses it."""
    lo, hi = np.inf, -np.inf
    bp, bv = poly[pi, 0, 0], poly[pi, 0, 1]
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        vi, vj = poly[pi, i, 1], poly[pi, j, 1]
        if abs(vi) < abs(bv):
            bp, bv = poly[pi, i, 0], vi
        if vi == 0.0:
            lo, hi = min(lo, poly[pi, i, 0]), max(hi, poly[pi, i, 0])
        elif (vi < 0.0) != (vj < 0.0) and vj != 0.0:
            p = poly[pi, i, 0] + vi / (vi - vj) * (poly[pi, j, 0] - poly[pi, i, 0])
            lo, hi = min(lo, p), max(hi, p)
    if lo <= hi:
        return 0.5 * (lo + hi), 0.0
    return bp, bv


@numba.njit(cache=True, nogil=True)
def _reduce(x, cols, scale, active, eps, limit, mask, values, bad, gave_up, first, stop):
    """Free-knot keys of tracks first..stop-1 (columns cols of x, each coordinate times scale) into mask and
    values (scaled back); bad marks tracks that need sampled keys. A track stops early (gave_up, no keys
    written) once it cannot end with fewer than limit keys. x is read where it lies (no scaled copy)."""
    t, d = x.shape[0], x.shape[2]
    kv = np.empty((t + 1, d))  # the track's key values, scaled
    poly = np.empty((2 * d + 1, MAX_VERTS, 2))  # coordinate c's polygon in slot cur[c], its next in the other of
    # c and d + c (the two swap, nothing is copied); 2d: scratch
    cur = np.empty(d, np.int64)
    nxt = np.empty(d, np.int64)
    qs = np.empty((2, MAX_VERTS))  # p + tau v of the polygon being cut (row 0) and of the scratch (row 1)
    cnt = np.empty(d, np.int64)
    ncnt = np.empty(d, np.int64)
    seg_t = np.empty(t + 1, np.int64)
    seg_poly = np.empty(((t + 1) * d, MAX_VERTS, 2))  # segment i's polygon of coordinate c at i * d + c
    seg_cnt = np.empty((t + 1, d), np.int64)
    for j in range(first, stop):
        col = cols[j]
        e = eps[j]
        s = 0
        last = -1
        nseg = 0
        for c in range(d):
            cur[c] = c
            cnt[c] = _rect(poly, c, -BIG, BIG)
        for k in range(t):
            if not active[k, j]:
                continue
            # Frame k's strip lo <= p + tau v <= hi cuts every coordinate's polygon. When one would empty (or
            # outgrow MAX_VERTS), the last active frame becomes a key and the cut is made again from there. (The
            # cut is written out here, not called: see the note above _rect.)
            tau = k - s
            for attempt in range(2):
                ok = True
                for c in range(d):
                    xv = x[k, col, c] * scale[c]
                    lo, hi = xv - e, xv + e
                    pc = cur[c]
                    q_lo, q_hi = np.inf, -np.inf
                    for i in range(cnt[c]):
                        q = poly[pc, i, 0] + tau * poly[pc, i, 1]
                        qs[0, i] = q
                        q_lo, q_hi = min(q_lo, q), max(q_hi, q)
                    m = -1  # the strip holds all of it: unchanged
                    if q_hi < lo or q_lo > hi:
                        m = 0
                    elif q_lo < lo or q_hi > hi:
                        # Cut by the side(s) it crosses, hi first (into the scratch slot when lo cuts too). A vertex
                        # within ON_LINE of a line counts as on it: kept, and no new vertex is made next to it.
                        # Without that, rounding adds near-copies of vertices at every cut and the polygons
                        # outgrow MAX_VERTS. A vertex's signed distance sgn (q - cut) is its p + tau v less the line,
                        # the same bits as sgn p + sgn tau v - sgn cut.
                        nxt[c] = pc + d if pc < d else pc - d
                        src, srow, m = pc, 0, cnt[c]
                        for side in range(2):
                            if side == 0:
                                if q_hi <= hi:
                                    continue
                                sgn, cut = 1.0, hi
                                dst = 2 * d if q_lo < lo else nxt[c]
                            else:
                                if q_lo >= lo:
                                    continue
                                sgn, cut = -1.0, lo
                                dst = nxt[c]
                            n_src, m = m, 0
                            tol = ON_LINE * (abs(cut) + 1.0)
                            gj = sgn * (qs[srow, 0] - cut)
                            for i in range(n_src):
                                i2 = i + 1 if i + 1 < n_src else 0
                                gi = gj
                                gj = sgn * (qs[srow, i2] - cut)
                                if gi <= tol:
                                    if m < MAX_VERTS:
                                        poly[dst, m, 0] = poly[src, i, 0]
                                        poly[dst, m, 1] = poly[src, i, 1]
                                        if side == 0:
                                            qs[1, m] = qs[srow, i]
                                    m += 1
                                if (gi < -tol and gj > tol) or (gi > tol and gj < -tol):
                                    f = gi / (gi - gj)
                                    if m < MAX_VERTS:
                                        pn = poly[src, i, 0] + f * (poly[src, i2, 0] - poly[src, i, 0])
                                        vn = poly[src, i, 1] + f * (poly[src, i2, 1] - poly[src, i, 1])
                                        poly[dst, m, 0] = pn
                                        poly[dst, m, 1] = vn
                                        if side == 0:
                                            qs[1, m] = pn + tau * vn
                                    m += 1
                            if m == 0 or m > MAX_VERTS:
                                break
                            src, srow = dst, 1
                    ncnt[c] = m
                    if m == 0 or m > MAX_VERTS - 4:
                        ok = False
                        break
                if ok:
                    for c in range(d):
                        if ncnt[c] > 0:
                            cnt[c] = ncnt[c]
                            cur[c] = nxt[c]
                    break
                if attempt == 1 or last <= s:
                    bad[j] = True  # on the second attempt it cannot happen with a free velocity: safety net only
                    break
                # The last active frame becomes a key; its window is where the segment can end.
                seg_t[nseg] = s
                span = last - s
                for c in range(d):
                    pc = cur[c]
                    seg_cnt[nseg, c] = cnt[c]
                    lo, hi = np.inf, -np.inf
                    for i in range(cnt[c]):
                        seg_poly[nseg * d + c, i, 0] = poly[pc, i, 0]
                        seg_poly[nseg * d + c, i, 1] = poly[pc, i, 1]
                        y = poly[pc, i, 0] + span * poly[pc, i, 1]
                        lo, hi = min(lo, y), max(hi, y)
                    cnt[c] = _rect(poly, pc, lo, hi)
                nseg += 1
                s = last
                tau = k - s
                if nseg + 2 >= limit[j] and not bad[j]:  # keys so far, the open segment's and the loop end's
                    gave_up[j] = True
                    break
            if gave_up[j]:
                break
            if not ok:
                continue
            last = k
        if last < 0 or gave_up[j]:
            continue  # never active, or not worth finishing: no keys
        seg_t[nseg] = s
        for c in range(d):
            seg_cnt[nseg, c] = cnt[c]
            for i in range(cnt[c]):
                seg_poly[nseg * d + c, i, 0] = poly[cur[c], i, 0]
                seg_poly[nseg * d + c, i, 1] = poly[cur[c], i, 1]
        nseg += 1
        # Backward: the loop-end key with the slowest last segment, then each key mid-way along its chord.
        mask[t, j] = True
        for c in range(d):
            p, v = _slowest(seg_poly, (nseg - 1) * d + c, seg_cnt[nseg - 1, c])
            kv[t, c] = p + v * (t - seg_t[nseg - 1])
            kv[seg_t[nseg - 1], c] = p
        mask[seg_t[nseg - 1], j] = True
        for i in range(nseg - 2, -1, -1):
            mask[seg_t[i], j] = True
            span = seg_t[i + 1] - seg_t[i]
            for c in range(d):
                kv[seg_t[i], c] = _on_line(seg_poly, i * d + c, seg_cnt[i, c], span, kv[seg_t[i + 1], c])
        # The bound, checked on what was built (numerical safety net).
        i = 0
        for k in range(t):
            while i + 1 < nseg and seg_t[i + 1] <= k:
                i += 1
            if not active[k, j]:
                continue
            a = seg_t[i]
            b = seg_t[i + 1] if i + 1 < nseg else t
            f = (k - a) / (b - a)
            for c in range(d):
                y = kv[a, c] + f * (kv[b, c] - kv[a, c])
                xv = x[k, col, c] * scale[c]
                if abs(y - xv) > e + SLACK * (e + abs(xv) + 1.0):
                    bad[j] = True
        if not bad[j]:  # the keys, scaled back (to values' dtype)
            for i in range(nseg + 1):
                kf = seg_t[i] if i < nseg else t
                for c in range(d):
                    values[kf, j, c] = kv[kf, c] / scale[c]


def block_tracks(t: int) -> int:
    """Tracks of t frames reduced together: BLOCK_TRACKS, fewer on long captures (their dense keys and jitter
    would otherwise take hundreds of MB a block)."""
    return min(BLOCK_TRACKS, max(16, BLOCK_CELLS // max(t, 1)))


def reduce_free(x: np.ndarray, active: np.ndarray, eps: float | np.ndarray) -> keys.Keys:
    """Keys for tracks x (T, N, D) within eps per coordinate where active, with free key values."""
    t, n, d = x.shape
    out = keys.Keys(np.zeros((t + 1, n), bool), np.zeros((t + 1, n, d)),
                    np.where(np.any(active, axis=0), np.argmax(active, axis=0), -1))
    size = block_tracks(t)
    for a in range(0, n, size):
        k, _ = _reduce_block(x, active[:, a:a + size], np.broadcast_to(np.asarray(eps, np.float64), (n,))[a:a + size],
                             None, cols=np.arange(a, min(a + size, n)))
        out.mask[:, a:a + size], out.values[:, a:a + size] = k.mask, k.values
    return out


def _reduce_block(x: np.ndarray, active: np.ndarray, eps: np.ndarray, limit: np.ndarray | None,
                  scale: np.ndarray | None = None, cols: np.ndarray | None = None,
                  dtype: type = np.float64) -> tuple[keys.Keys, np.ndarray]:
    """reduce_free of the tracks cols (default all) of x (T, N, D), each coordinate times scale (the keys' values
    scaled back, as dtype), giving up (bool (n,), no keys) on each track that cannot end with fewer than limit (n,)
    keys. active (T, n) and eps (n,) are the chosen tracks'."""
    cols = np.arange(x.shape[1], dtype=np.int64) if cols is None else np.ascontiguousarray(cols, np.int64)
    t, n, d = x.shape[0], len(cols), x.shape[2]
    if x.dtype not in (np.float32, np.float64):
        x = x.astype(np.float64)
    scale = np.ones(d) if scale is None else np.ascontiguousarray(scale, np.float64)
    active = np.ascontiguousarray(active, bool)
    eps = np.require(eps, np.float64, ["C", "W"])  # writable: a read-only eps was a kernel signature of its own
    lim = np.full(n, np.iinfo(np.int64).max, np.int64) if limit is None else np.ascontiguousarray(limit, np.int64)
    mask, values = np.zeros((t + 1, n), bool), np.zeros((t + 1, n, d), dtype)
    bad, gave_up = np.zeros(n, bool), np.zeros(n, bool)
    if n and t:
        parallel.threaded(_reduce, n, x, cols, scale, active, eps, lim, mask, values, bad, gave_up)
    if bad.any():  # numerically awkward tracks: sampled keys, always valid
        fb = keys.reduce(np.take(x, cols[bad], axis=1) * scale, np.compress(bad, active, axis=1), eps[bad])
        mask[:, bad], values[:, bad] = fb.mask, fb.values / scale
    return keys.Keys(mask, values, np.zeros(0, np.int64)), gave_up


def lean_deg(xy: np.ndarray, active: np.ndarray, first: int = 0) -> np.ndarray:
    """Per track of 2D points xy[:, first:first + n] (T, n, 2m), n = active.shape[1], the angle (degrees) of its
    jitter: atan2 of the summed |second difference| in y and in x over frames active three in a row; NaN for a
    track that never bends. (xy whole and first, not a slice of it: the kernel then sees one array layout.)"""
    n = active.shape[1]
    if not 0 <= first <= first + n <= xy.shape[1] or active.shape[0] != xy.shape[0]:  # the kernel reads unchecked
        raise ValueError(f"active {active.shape} from track {first} does not fit xy {xy.shape}")
    ex, ey = np.zeros(n), np.zeros(n)
    _jitter(xy, np.ascontiguousarray(active, np.bool_), first, ex, ey)
    return np.where(ex + ey > 0, np.degrees(np.arctan2(ey, ex)), np.nan)


@numba.njit(cache=True, nogil=True)
def _jitter(xy, active, first, ex, ey) -> None:
    """lean_deg's sums into ex, ey (n,) for tracks first.. of xy: each second difference in xy's dtype (as np.diff
    makes it), summed in float64 (numpy's where, abs and sum over (T, N, 2m) temporaries were a noticeable share
    of the 128k-triangle face's writer)."""
    t, n, d = xy.shape[0], active.shape[1], xy.shape[2]
    for k in range(2, t):
        for i in range(n):
            if not (active[k, i] and active[k - 1, i] and active[k - 2, i]):
                continue
            j = first + i
            sx, sy = 0.0, 0.0
            for c in range(0, d - 1, 2):
                sx += abs((xy[k, j, c] - xy[k - 1, j, c]) - (xy[k - 1, j, c] - xy[k - 2, j, c]))
                sy += abs((xy[k, j, c + 1] - xy[k - 1, j, c + 1]) - (xy[k - 1, j, c + 1] - xy[k - 2, j, c + 1]))
            ex[i] += sx
            ey[i] += sy


def point_keys(xy: np.ndarray, active: np.ndarray, radius: float | np.ndarray,
               shapes: tuple[float, ...] | None = None, best: keys.Keys | None = None,
               exhaustive: bool = False, progress: Progress = no_progress) -> keys.Keys:
    """Free-knot keys for tracks of 2D points xy (T, N, 2m), each point within Euclidean radius where active;
    with best, per track whichever of best and the shapes' keys has fewest (best on ties; best's arrays are
    updated in place and returned). The values are stored as float32 (dense over T + 1 frames, they are the
    encoder's largest array; budget.float_err covers the rounding); the tracks are read where they lie and
    reduced in float64.

    Without best the first shape is reduced for every track. Unless exhaustive, a track then tries only the
    further shape nearest the lean of its jitter (``lean_deg``; the rectangle on its side of the square), and none
    when it never bends: on the capture-like face that keeps nearly all of the keys trying every shape on every
    track saves, for much less CPU.

    progress("keys", fraction of the work done) before each block of tracks (without best, the first shape's
    pass counts as half of it)."""
    shapes = SHAPES_DEG if shapes is None else shapes
    t, n = xy.shape[:2]
    m = xy.shape[2] // 2
    r = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    if best is None:
        best, _ = shape_keys(xy, active, r, shapes[0], progress=span(progress, 0.0, 0.5))
        shapes = shapes[1:]
        progress = span(progress, 0.5, 1.0)
    angles = np.array(shapes, np.float64)
    size = block_tracks(t)
    for b in range(0, n, size):  # blocks of tracks: the dense keys and the lean stay small
        progress("keys", b / max(n, 1))
        sl = slice(b, b + size)
        nearest = None
        if not exhaustive and len(shapes) > 1:
            lean = lean_deg(xy, active[:, sl], b)
            nearest = np.where(np.isnan(lean), np.nan, angles[np.argmin(np.abs(np.nan_to_num(lean)[:, None] - angles),
                                                                          axis=1)])
        for a in shapes:
            # A shape only replaces best where it needs fewer keys: tracks stop as soon as they cannot.
            idx = np.arange(b, min(b + size, n)) if nearest is None else b + np.flatnonzero(nearest == a)
            if not len(idx):
                continue
            limit = np.take(best.mask, idx, axis=1).sum(axis=0)
            k, gave_up = _reduce_block(xy, np.take(active, idx, axis=1), r[idx], limit, _scale(a, m), idx, np.float32)
            win = np.flatnonzero(~gave_up & (k.mask.sum(axis=0) < limit))
            best.mask[:, idx[win]], best.values[:, idx[win]] = k.mask[:, win], k.values[:, win]
    return best


def shape_keys(xy: np.ndarray, active: np.ndarray, radius: float | np.ndarray, deg: float,
               limit: np.ndarray | None = None, progress: Progress = no_progress) -> tuple[keys.Keys, np.ndarray]:
    """Free-knot keys for tracks of 2D points xy (T, N, 2m) within the rectangle of angle deg inscribed in each
    point's circle of radius where active (values float32, as point_keys'). With limit (N,), a track gives up
    (gave_up (N,) True, no keys) once it cannot end with fewer than limit keys. progress("keys", fraction of the
    tracks done) before each block."""
    t, n = xy.shape[:2]
    m = xy.shape[2] // 2
    r = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    out = keys.Keys(np.zeros((t + 1, n), bool), np.zeros((t + 1, n, 2 * m), np.float32),
                    np.where(np.any(active, axis=0), np.argmax(active, axis=0), -1))
    gave_up = np.zeros(n, bool)
    size = block_tracks(t)
    for b in range(0, n, size):  # blocks of tracks: the dense keys stay small
        progress("keys", b / max(n, 1))
        sl = slice(b, b + size)
        k, gave_up[sl] = _reduce_block(xy, active[:, sl], r[sl], None if limit is None else limit[sl],
                                       _scale(deg, m), np.arange(b, min(b + size, n)), np.float32)
        out.mask[:, sl], out.values[:, sl] = k.mask, k.values
    return out, gave_up


def _scale(deg: float, m: int) -> np.ndarray:
    """Per coordinate of m points, the factor that turns the rectangle of half-widths r cos a (x) and r sin a (y),
    inscribed in the circle of radius r, into the square of half-width r. Captured jitter is rarely the same on
    both axes, so the shape that needs fewest keys differs from track to track."""
    a = math.radians(deg)
    return np.tile([1 / math.cos(a), 1 / math.sin(a)], m)
