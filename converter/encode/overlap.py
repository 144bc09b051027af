"""Which paths may touch on screen: the pairs whose drawing order must be kept (converter.encode.groups.reorder).

Two paths that never come within a stroke's spill of each other in a frame where both are drawn can be drawn
in either order without changing a pixel. ``overlap_pairs`` finds the others: candidates from a uniform grid of
bounding boxes per block of frames, then an exact test per candidate and frame (boxes, then a separating-axis
test on the two triangles). The exact test stops at the first frame where a pair meets; that early exit is a
loop numpy cannot express, so it is compiled with numba. Arithmetic is float32, as the positions are stored.
"""

from __future__ import annotations

import numba
import numpy as np

from converter.arrays import lexsort_ints
from converter.encode import parallel

# Frames per candidate-search block: a block's boxes hold its frames' motion, so the best block is about as many
# frames as a triangle takes to move its own size (any size finds the same pairs; the exact test decides per frame).
# On the capture-like face (8 px triangles moving ~1 px a frame) 6-16 frames were equally fast, 2 or 24 a third
# slower; on its 128k-triangle subdivision (2 px triangles) 2 frames took 8.2 s where 8 took 14.6 and 16 26.4.
BLOCK_RANGE = (2, 32)
MOTION_FRAMES = 50  # the motion a frame is the median over the first this many frames
STROKE_MARGIN_PX = 0.5  # two paths closer than this may share stroke pixels: their order is kept
EMPTY = -1  # a free slot of a PairSet's table
PAIRSET_BITS = 16  # a PairSet starts with 2^16 slots (512 KB) and doubles when half full


# The compiled helpers address a triangle as (pts, frame, path), never as a slice, and are inlined: a slice or an
# array argument is reference-counted with atomic operations on every call, contended between threads.
@numba.njit(cache=True, nogil=True, inline="always")
def _span(pts, f, a, nx, ny):
    """Lowest and highest projection of triangle pts[f, a] (3, 2) on the axis (nx, ny)."""
    p0 = nx * pts[f, a, 0, 0] + ny * pts[f, a, 0, 1]
    p1 = nx * pts[f, a, 1, 0] + ny * pts[f, a, 1, 1]
    p2 = nx * pts[f, a, 2, 0] + ny * pts[f, a, 2, 1]
    return min(min(p0, p1), p2), max(max(p0, p1), p2)


@numba.njit(cache=True, nogil=True, inline="always")
def _apart(pts, f, a, b, margin) -> bool:
    """Triangles pts[f, a] and pts[f, b] (3, 2) are more than margin apart along one of their 6 edge normals (a
    negative margin: overlap by less than -margin there)."""
    for side in range(2):
        tri = a if side == 0 else b
        for i in range(3):
            k = (i + 1) % 3
            nx = -(pts[f, tri, k, 1] - pts[f, tri, i, 1])
            ny = pts[f, tri, k, 0] - pts[f, tri, i, 0]
            a_lo, a_hi = _span(pts, f, a, nx, ny)
            b_lo, b_hi = _span(pts, f, b, nx, ny)
            # Gap of the two projections (minus their overlap): beyond the edge test's gap when one projection
            # holds the other, which only a negative margin (interiors overlapping by -margin) can see.
            if max(a_lo, b_lo) - min(a_hi, b_hi) > margin * np.sqrt(nx * nx + ny * ny):
                return True
    return False


@numba.njit(cache=True, nogil=True)
def _meet(pts, on, la, lb, margin, out, first, stop) -> None:
    """out[c] for candidates first..stop-1: paths la[c], lb[c] come within margin in a frame both draw."""
    for c in range(first, stop):
        a, b = la[c], lb[c]
        for f in range(pts.shape[0]):
            if not (on[f, a] and on[f, b]):
                continue
            near = True
            for ax in range(2):
                lo_a = min(min(pts[f, a, 0, ax], pts[f, a, 1, ax]), pts[f, a, 2, ax])
                hi_a = max(max(pts[f, a, 0, ax], pts[f, a, 1, ax]), pts[f, a, 2, ax])
                lo_b = min(min(pts[f, b, 0, ax], pts[f, b, 1, ax]), pts[f, b, 2, ax])
                hi_b = max(max(pts[f, b, 0, ax], pts[f, b, 1, ax]), pts[f, b, 2, ax])
                if max(lo_a, lo_b) > min(hi_a, hi_b) + margin:
                    near = False
            if near and not _apart(pts, f, a, b, margin):
                out[c] = True
                break


def apart(pa: np.ndarray, pb: np.ndarray, margin: float) -> np.ndarray:
    """Bool (...): triangles pa, pb (..., 3, 2) are more than margin apart along one of their 6 edge normals
    (a separating-axis test; False may still mean apart, never the reverse)."""
    a, b = np.broadcast_arrays(np.asarray(pa, np.float32), np.asarray(pb, np.float32))
    shape = a.shape[:-2]
    pairs = np.ascontiguousarray(np.stack([a.reshape(-1, 3, 2), b.reshape(-1, 3, 2)], axis=1))  # (N, 2, 3, 2)
    return _apart_each(pairs, np.float32(margin)).reshape(shape)


@numba.njit(cache=True, nogil=True)
def _apart_each(pairs, margin):
    """_apart of each pair of triangles pairs[i, 0], pairs[i, 1]."""
    out = np.empty(pairs.shape[0], np.bool_)
    for i in range(pairs.shape[0]):
        out[i] = _apart(pairs, i, 0, 1, margin)
    return out


@numba.njit(cache=True, nogil=True)
def _boxes(pts, on, grow):
    """Per path, the box (lo, hi (n, 2)) of its triangles pts (B, n, 3, 2) over the frames on (B, n) where it is
    drawn, grown by grow on every side."""
    n = pts.shape[1]
    lo = np.full((n, 2), np.inf, np.float32)
    hi = np.full((n, 2), -np.inf, np.float32)
    for f in range(pts.shape[0]):
        for a in range(n):
            if not on[f, a]:
                continue
            for v in range(3):
                for ax in range(2):
                    lo[a, ax] = min(lo[a, ax], pts[f, a, v, ax])
                    hi[a, ax] = max(hi[a, ax], pts[f, a, v, ax])
    return lo - grow, hi + grow


def _cell_lists(lo: np.ndarray, hi: np.ndarray, cell: float,
                band: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes [lo, hi] (N, 2) of bands (N,) on a grid of side cell: (cell key, box) for every cell a box covers,
    sorted by key, then by band, then by box; and each box's lowest cell (N, 2)."""
    c0 = np.floor(lo / cell).astype(np.int64)
    span = np.floor(hi / cell).astype(np.int64) - c0 + 1
    n_cells = span[:, 0] * span[:, 1]
    owner = np.repeat(np.arange(len(lo)), n_cells)
    local = np.arange(int(n_cells.sum())) - np.repeat(np.cumsum(n_cells) - n_cells, n_cells)
    sx = np.repeat(span[:, 0], n_cells)
    cx = np.repeat(c0[:, 0], n_cells) + local % sx
    cy = np.repeat(c0[:, 1], n_cells) + local // sx
    key = _cell_key(cx, cy, c0[:, 0].min(), c0[:, 1].min())
    order = lexsort_ints((band[owner], key))  # stable, and owner rises already: then by box
    return key[order], owner[order], c0


@numba.njit(cache=True, nogil=True)
def _cell_key(cx, cy, x0, y0):
    """One integer per grid cell (cx, cy) (scalars or arrays) at or past the cell (x0, y0)."""
    return (cx - x0) * (1 << 31) + (cy - y0)


@numba.njit(cache=True, nogil=True)
def _candidates(key, owner, c0, band, lo, hi, out) -> int:
    """Pairs (a < b) of boxes of different band that meet, into out (M, 2) (only counted once it is full). The
    cell lists come from _cell_lists with band: a cell's boxes of one band are consecutive, so only pairs across
    its bands are looked at, and a cell inside one band costs one pass (on the 128k-triangle face, 43 % of the
    cells and half the pairs within cells: 19.7 -> 13.8 s over its 335 frames).

    Each pair is reported in one cell only: the cell holding the low corner of the two boxes' intersection,
    max(c0[a], c0[b]), which both cover when they meet."""
    m = 0
    start = 0
    x0, y0 = c0[:, 0].min(), c0[:, 1].min()
    while start < len(key):
        stop = start + 1
        while stop < len(key) and key[stop] == key[start]:
            stop += 1
        g0 = start
        while g0 < stop:  # one band's boxes g0..g1-1 against the cell's later bands
            g1 = g0 + 1
            while g1 < stop and band[owner[g1]] == band[owner[g0]]:
                g1 += 1
            for i in range(g0, g1):
                a = owner[i]
                for j in range(g1, stop):
                    b = owner[j]
                    if (max(lo[a, 0], lo[b, 0]) > min(hi[a, 0], hi[b, 0])
                            or max(lo[a, 1], lo[b, 1]) > min(hi[a, 1], hi[b, 1])):
                        continue
                    if _cell_key(max(c0[a, 0], c0[b, 0]), max(c0[a, 1], c0[b, 1]), x0, y0) != key[start]:
                        continue
                    if m < out.shape[0]:
                        out[m, 0], out[m, 1] = min(a, b), max(a, b)
                    m += 1
            g0 = g1
        start = stop
    return m


class PairSet:
    """A set of pair codes (int64 >= 0), open addressing in one int64 table kept at most half full: memory follows
    the pairs found, not the paths squared (a bitmap of 27k paths would take 712 MB) nor the blocks (a list of
    each block's finds, deduplicated at the end, peaked 1.8 GB on a 4,000-frame capture of the ICT head)."""

    def __init__(self, bits: int | None = None):
        bits = PAIRSET_BITS if bits is None else bits
        self.table = np.full(1 << bits, EMPTY, np.int64)
        self.shift = 64 - bits
        self.count = 0

    def absent(self, codes: np.ndarray) -> np.ndarray:
        """Bool (N,): which codes are not in the set."""
        out = np.empty(len(codes), np.bool_)
        _absent(self.table, self.shift, np.ascontiguousarray(codes, np.int64), out)
        return out

    def add(self, codes: np.ndarray) -> None:
        """Add codes (duplicates allowed)."""
        codes = np.ascontiguousarray(codes, np.int64)
        if 2 * (self.count + len(codes)) > len(self.table):
            old = self.table[self.table != EMPTY]
            bits = max(64 - self.shift, int(2 * (self.count + len(codes)) - 1).bit_length() + 1)
            self.table = np.full(1 << bits, EMPTY, np.int64)
            self.shift = 64 - bits
            self.count = _add(self.table, self.shift, old)
        self.count += _add(self.table, self.shift, codes)

    def sorted(self) -> np.ndarray:
        """The codes, ascending."""
        return np.sort(self.table[self.table != EMPTY])


@numba.njit(cache=True, nogil=True, inline="always")
def _slot(code, shift):
    """Fibonacci hashing: the top bits of code times 2^64 / golden ratio."""
    return np.int64((np.uint64(code) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(shift))


@numba.njit(cache=True, nogil=True)
def _absent(table, shift, codes, out):
    """out[i] = codes[i] is not in table."""
    mask = len(table) - 1
    for i in range(len(codes)):
        c = codes[i]
        s = _slot(c, shift)
        while table[s] != c and table[s] != EMPTY:
            s = (s + 1) & mask
        out[i] = table[s] == EMPTY


@numba.njit(cache=True, nogil=True)
def _add(table, shift, codes) -> int:
    """Insert codes into table (with room); the number newly inserted."""
    mask = len(table) - 1
    n = 0
    for i in range(len(codes)):
        c = codes[i]
        s = _slot(c, shift)
        while table[s] != c and table[s] != EMPTY:
            s = (s + 1) & mask
        if table[s] == EMPTY:
            table[s] = c
            n += 1
    return n


def block_frames(xy_paths: np.ndarray, corners: np.ndarray | None = None) -> int:
    """Frames per candidate-search block for overlap_pairs' tracks: the median triangle's size (largest side of its
    box at frame 0) over the median distance a point moves in a frame (largest axis), within BLOCK_RANGE."""
    head = xy_paths[:MOTION_FRAMES + 1]
    first = np.take(head[0], corners, axis=0) if corners is not None else head[0]  # (P, 3, 2)
    if not first.size or len(head) < 2:
        return BLOCK_RANGE[0]
    size = float(np.median((first.max(axis=1) - first.min(axis=1)).max(axis=1)))
    step = float(np.median(np.abs(np.diff(head, axis=0)).max(axis=-1)))
    ratio = size / step if step > 0 else np.inf
    if not np.isfinite(ratio):  # nothing moves (or the positions are not finite): the widest block
        return BLOCK_RANGE[1]
    return int(np.clip(round(ratio), *BLOCK_RANGE))


def overlap_pairs(xy_paths: np.ndarray, active: np.ndarray, block: int | None = None,
                  margin: float = STROKE_MARGIN_PX, band: np.ndarray | None = None,
                  corners: np.ndarray | None = None) -> np.ndarray:
    """(E, 2) path pairs i < j that may come within margin px of each other in a frame where both are drawn.
    xy_paths (T, P, 3, 2) px, or with corners (P, 3) vertex ids into xy_paths (T, V, 2), gathered a block of
    frames at a time (no (T, P, 3, 2) copy).

    Candidates: per block of frames, pairs whose bounding boxes over the block's drawn frames (grown by
    margin / 2, the stroke's spill) meet, found through a uniform grid. Each candidate is then tested in the
    frames of the block where both are drawn: their boxes, then the separating-axis test (``apart``). A pair is
    kept unless every such frame shows it apart, so the result is conservative. A pair found in one block is not
    tested again. A negative margin asks for pairs whose interiors overlap by more than -margin along every axis
    (converter.encode.order). With band (P,), only pairs of different bands are returned (``reorder`` keeps each
    band's own order anyway). On the capture-like face this exact test halves the runs the box test alone leaves.
    block: frames per block (default ``block_frames``)."""
    t, p = active.shape
    block = block_frames(xy_paths, corners) if block is None else block
    xy32 = xy_paths if corners is not None else np.asarray(xy_paths, np.float32)
    m32 = np.float32(margin)
    found = PairSet()
    last_m = 0
    for k0 in range(0, t, block):
        act = active[k0:k0 + block]
        idx = np.flatnonzero(act.any(axis=0))
        if len(idx) < 2:
            continue
        if corners is None:
            pts = xy32[k0:k0 + block, idx]  # (B, n, 3, 2)
        else:
            pts = np.asarray(np.take(xy32[k0:k0 + block], corners[idx], axis=1), np.float32)
        on = np.take(act, idx, axis=1)
        lo, hi = _boxes(pts, on, np.float32(margin / 2))
        cell = max(1.5 * float(np.median((hi - lo).max(axis=1))), 1.0)
        own_band = band[idx] if band is not None else np.arange(len(idx))  # most neighbours share a band
        key, owner, c0 = _cell_lists(lo, hi, cell, own_band)
        out = np.empty((max(4 * len(idx), last_m + last_m // 4), 2), np.int64)  # blocks alike: rarely twice
        m = last_m = _candidates(key, owner, c0, own_band, lo, hi, out)
        if m > len(out):
            out = np.empty((m, 2), np.int64)
            _candidates(key, owner, c0, own_band, lo, hi, out)
        la, lb = out[:m, 0], out[:m, 1]
        glob = idx[la] * p + idx[lb]
        fresh = found.absent(glob)  # a pair found in an earlier block is not tested again
        la, lb, glob = la[fresh], lb[fresh], glob[fresh]
        meet = np.zeros(len(glob), bool)
        if len(glob):
            parallel.threaded(_meet, len(glob), pts, on, la, lb, m32, meet)
        found.add(glob[meet])
    code = found.sorted()
    return np.column_stack([code // p, code % p])
