"""Which paths may touch on screen: the pairs whose drawing order must be kept (converter.encode.groups.reorder).

Two paths that never come within a stroke's spill of each other in a frame where both are drawn can be drawn
in either order without changing a pixel. ``overlap_pairs`` finds the others: candidates from a uniform grid of
bounding boxes per block of frames, then an exact test per candidate and frame (boxes, then a separating-axis
test on the two triangles). The exact test stops at the first frame where a pair meets; that early exit is a
loop numpy cannot express, so it is compiled with numba. Arithmetic is float32, as the positions are stored.
A box over more than BIG_CELLS cells (a part blown up on screen, a vertex near the eye plane) is tested against
every other box directly instead: on the grid it would take an entry per cell it covers, billions of them.
"""

from __future__ import annotations

from functools import partial

import numba
import numpy as np

from converter.arrays import lexsort_ints
from converter.encode import parallel
from converter.options import Progress, no_progress

# Frames per candidate-search block: a block's boxes hold its frames' motion, so the best block is about as many
# frames as a triangle takes to move its own size (any size finds the same pairs; the exact test decides per frame).
# On the capture-like face (8 px triangles moving ~1 px a frame) a middle range of block lengths were equally fast,
# much shorter or longer ones slower; on its 128k-triangle subdivision (2 px triangles) the shortest blocks were
# the fastest by far.
BLOCK_RANGE = (2, 32)
MOTION_FRAMES = 50  # the motion a frame is the median over the first this many frames
CELL_BOXES = 1.5  # grid cell side, in median box sides (largest side) of the block
STROKE_MARGIN_PX = 0.5  # two paths closer than this may share stroke pixels: their order is kept
EMPTY = -1  # a free slot of a PairSet's table
PAIRSET_BITS = 12  # a PairSet starts with 2^12 slots (64 KB) and grows when half full
TILE = 8  # a PairSet keeps the pairs of TILE x TILE paths in one 64-bit word
SLOT_GROUP = 2  # ... and the 2^2 tiles of a row whose numbers differ in their low 2 bits in one 64-byte line
BIG_CELLS = 4096  # a box over more cells than this is tested against every box directly, not through the grid
BIG_CHUNK = 256  # ... that many big boxes at a time (a (chunk, boxes) temporary)


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
                band: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Boxes [lo, hi] (N, 2) of bands (N,) on a grid of side cell: an entry for every cell a box covers, sorted by
    cell (along a Z-order curve, so consecutive cells hold nearby paths), then by band, then by box. Per entry:
    its cell's key, its box's number, box (lo, hi as 4 values), band, and a flag (bit 0: the cell is the box's
    lowest in x, bit 1: in y), each array in entry order so a cell's entries are read in one sweep."""
    key, owner, flag = _entries(lo, hi, np.float32(cell))
    order = lexsort_ints((band[owner], key))  # stable, and owner rises already: then by box
    owner = owner[order]
    return key[order], owner, np.take(np.concatenate([lo, hi], axis=1), owner, axis=0), band[owner], flag[order]


@numba.njit(cache=True, nogil=True)
def _entries(lo, hi, cell):
    """_cell_lists' entries by box: (cell key, box, flag) for each cell each box covers."""
    n = len(lo)
    c0 = np.empty((n, 2), np.int64)
    c1 = np.empty((n, 2), np.int64)
    total = 0
    for a in range(n):
        for ax in range(2):
            c0[a, ax] = np.int64(np.floor(lo[a, ax] / cell))
            c1[a, ax] = np.int64(np.floor(hi[a, ax] / cell))
        total += (c1[a, 0] - c0[a, 0] + 1) * (c1[a, 1] - c0[a, 1] + 1)
    x0, y0 = c0[:, 0].min(), c0[:, 1].min()
    key = np.empty(total, np.int64)
    owner = np.empty(total, np.int64)
    flag = np.empty(total, np.uint8)
    e = 0
    for a in range(n):
        for cy in range(c0[a, 1], c1[a, 1] + 1):
            for cx in range(c0[a, 0], c1[a, 0] + 1):
                key[e] = np.int64(_z(np.uint64(cx - x0), np.uint64(cy - y0)))
                owner[e] = a
                flag[e] = (cx == c0[a, 0]) | ((cy == c0[a, 1]) << 1)
                e += 1
    return key, owner, flag


@numba.njit(cache=True, nogil=True)
def _candidates(key, owner, box, band, flag, idx, table, shift, nb, out, first, last):
    """Pairs (a < b) of boxes of different band that meet and whose paths (idx[a], idx[b]) are not yet in the
    PairSet table, from the cells whose first entry lies in first..last-1, as (buffer, M): the pairs are
    buffer[:M], buffer being out (K, 2) or, when more than K pairs come, a larger one, which the caller passes in
    for the next block (a fresh buffer per block, grown by doubling, faulted its pages in again on every block of
    the 128k-triangle face). Each cell is read by the one call whose slice holds its first entry, so calls on slices
    of the entries find the pairs of one call on all of them, in the same order, and may run at once (the table
    is only read).

    From the entries of _cell_lists: a cell's boxes of one band are consecutive, so only pairs across its bands
    are looked at, and a cell inside one band costs one pass (on the 128k-triangle face, many of the cells and of
    the pairs within cells, which cut the search's time).

    Each pair is reported in one cell only: the cell holding the low corner of the two boxes' intersection, which
    both cover when they meet: there, in x and in y, the cell is the lowest of one of the two boxes."""
    near = np.empty(len(key), np.bool_)
    m = 0
    start = first
    while 0 < start < len(key) and key[start] == key[start - 1]:  # a cell begun before first: not this call's
        start += 1
    while start < min(last, len(key)):
        stop = start + 1
        while stop < len(key) and key[stop] == key[start]:
            stop += 1
        g0 = start
        while g0 < stop:  # one band's boxes g0..g1-1 against the cell's later bands
            g1 = g0 + 1
            while g1 < stop and band[g1] == band[g0]:
                g1 += 1
            for i in range(g0, g1):
                # The box tests against the cell's later bands first, branch-free (a loop the compiler can vectorise),
                # then the look-ups for those that pass.
                x0, y0, x1, y1, fi = box[i, 0], box[i, 1], box[i, 2], box[i, 3], flag[i]
                for j in range(g1, stop):
                    near[j - g1] = ((max(x0, box[j, 0]) <= min(x1, box[j, 2]))
                                    & (max(y0, box[j, 1]) <= min(y1, box[j, 3])) & ((fi | flag[j]) == 3))
                for j in range(g1, stop):
                    if not near[j - g1]:
                        continue
                    u, v = min(owner[i], owner[j]), max(owner[i], owner[j])
                    if _has(table, shift, nb, idx[u], idx[v]):
                        continue
                    if m == len(out):
                        grown = np.empty((max(2 * m, 16), 2), np.int64)
                        for r in range(m):  # not grown[:m] = out: its shape check's message was slow to compile
                            grown[r, 0], grown[r, 1] = out[r, 0], out[r, 1]
                        out = grown
                    out[m, 0], out[m, 1] = u, v
                    m += 1
            g0 = g1
        start = stop
    return out, m


class PairSet:
    """A set of pairs a < b of paths 0..n-1, as a sparse bitmap: one bit per pair in 8 x 8 tiles of pairs, each
    tile a 64-bit word beside its number in an open-addressing table (kept at most half full).

    Memory follows the pairs found, not the paths squared (a bitmap of 27k paths would take 712 MB) nor the
    blocks (a list of each block's finds, deduplicated at the end, peaked high on a long capture of the ICT head).
    With paths numbered along the screen (``overlap_pairs``), a path's partners are mostly its neighbours' too:
    the millions of pairs of the 128k-triangle bench face fill far fewer tiles, and the look-ups of its search
    mostly meet tiles read just before. A table of one hashed slot per pair, several times larger, missed the
    cache on most look-ups, which took several times as long."""

    def __init__(self, n: int, bits: int | None = None):
        bits = PAIRSET_BITS if bits is None else bits
        self.n = n
        self.tiles = max(1, (n + TILE - 1) // TILE)  # tiles a side
        self.table = _table(1 << bits)  # (tile number, word) per slot
        self.shift = 64 - bits
        self.used = 0  # slots holding a tile
        self.count = 0  # pairs

    def has(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Bool (N,): which pairs (a[i] < b[i]) are in the set."""
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        out = np.empty(len(a), np.bool_)
        _has_each(self.table, self.shift, self.tiles, a, b, out)
        return out

    def add(self, a: np.ndarray, b: np.ndarray) -> None:
        """Add the pairs (a[i] < b[i]) (duplicates allowed)."""
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        if 2 * (self.used + len(a)) > len(self.table):  # room for every pair in a new tile
            bits = int(2 * (self.used + len(a)) - 1).bit_length()
            old = self.table
            self.table = _table(1 << bits)
            self.shift = 64 - bits
            _rehash(old, self.table, self.shift)
        used, added = _add(self.table, self.shift, self.tiles, a, b)
        self.used += used
        self.count += added

    def pairs(self, relabel: np.ndarray | None = None) -> np.ndarray:
        """The pairs (E, 2), sorted, with each path a renamed to relabel[a] (relabel: a permutation of 0..n-1,
        default none) and each pair written (smaller, larger)."""
        relabel = np.arange(self.n, dtype=np.int64) if relabel is None else np.asarray(relabel, np.int64)
        code = np.empty(self.count, np.int64)  # smaller * n + larger: one array sorted in place (the millions of
        # pairs of the 128k-triangle face were slow as separate arrays relabelled, compared and sorted)
        _codes(self.table, self.tiles, relabel, self.n, code)
        code.sort()
        out = np.empty((len(code), 2), np.int64)
        np.divmod(code, max(self.n, 1), out=(out[:, 0], out[:, 1]))
        return out


def _table(slots: int) -> np.ndarray:
    """An empty PairSet table of slots (tile, word) rows, starting on a 64-byte line (numpy's large arrays start
    16 bytes past a page: a group of 4 slots would straddle two lines)."""
    raw = np.full((slots + 3, 2), EMPTY, np.int64)
    first = (-raw.ctypes.data % 64) // 16
    return raw[first:first + slots]


@numba.njit(cache=True, nogil=True, inline="always")
def _slot(code, shift):
    """The first slot to try for tile number code in a table of 2^(64 - shift) slots: Fibonacci hashing (the top
    bits of the product with 2^64 / golden ratio) of code without its low SLOT_GROUP bits, then those bits. The
    search looks up a path's pairs with its neighbours, tiles of one row: on the 128k-triangle bench face its
    look-ups took less CPU with 4 of a row to a line than with every tile hashed apart."""
    g = min(SLOT_GROUP, 64 - shift)
    low = code & ((1 << g) - 1)
    if shift + g >= 64:  # a table of 2^g slots or fewer
        return low
    return (np.int64((np.uint64(code >> g) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(shift + g)) << g) | low


@numba.njit(cache=True, nogil=True, inline="always")
def _find(table, shift, tile):
    """The slot of tile in table, or the empty slot where it would go."""
    mask = len(table) - 1
    s = _slot(tile, shift)
    while table[s, 0] != tile and table[s, 0] != EMPTY:
        s = (s + 1) & mask
    return s


@numba.njit(cache=True, nogil=True, inline="always")
def _has(table, shift, nb, a, b) -> bool:
    """Pair a < b is in the PairSet table of nb tiles a side."""
    s = _find(table, shift, (a // TILE) * nb + b // TILE)
    return table[s, 0] != EMPTY and (table[s, 1] >> ((a % TILE) * TILE + b % TILE)) & 1 == 1


@numba.njit(cache=True, nogil=True)
def _has_each(table, shift, nb, a, b, out):
    """out[i] = pair a[i] < b[i] is in table."""
    for i in range(len(a)):
        out[i] = _has(table, shift, nb, a[i], b[i])


@numba.njit(cache=True, nogil=True)
def _add(table, shift, nb, a, b):
    """Insert the pairs a[i] < b[i] into table (with room): (tiles begun, pairs new)."""
    used, added = 0, 0
    for i in range(len(a)):
        tile = (a[i] // TILE) * nb + b[i] // TILE
        s = _find(table, shift, tile)
        if table[s, 0] == EMPTY:
            table[s, 0], table[s, 1] = tile, 0
            used += 1
        bit = np.int64(1) << ((a[i] % TILE) * TILE + b[i] % TILE)
        if table[s, 1] & bit == 0:
            table[s, 1] |= bit
            added += 1
    return used, added


@numba.njit(cache=True, nogil=True)
def _rehash(old, table, shift) -> None:
    """Move the tiles of old into the empty, larger table."""
    for i in range(len(old)):
        if old[i, 0] != EMPTY:
            s = _find(table, shift, old[i, 0])
            table[s, 0], table[s, 1] = old[i, 0], old[i, 1]


@numba.njit(cache=True, nogil=True)
def _codes(table, nb, relabel, n, out) -> None:
    """Every pair (a, b) of table into out as min * n + max of relabel[a], relabel[b]."""
    m = 0
    for i in range(len(table)):
        tile, word = table[i, 0], table[i, 1]
        if tile == EMPTY:
            continue
        for bit in range(TILE * TILE):
            if (word >> bit) & 1:
                a = relabel[(tile // nb) * TILE + bit // TILE]
                b = relabel[(tile % nb) * TILE + bit % TILE]
                out[m] = min(a, b) * n + max(a, b)
                m += 1


def screen_order(first: np.ndarray) -> np.ndarray:
    """A numbering of paths along the screen: the order (P,) of their points first (P, 2) px along a Z-order
    curve of 1 px cells (non-finite points last), so paths near on screen are mostly near in number."""
    ok = np.isfinite(first).all(axis=1)
    cells = np.zeros((len(first), 2), np.uint64)
    if ok.any():
        q = np.floor(first[ok] - first[ok].min(axis=0))
        cells[ok] = np.minimum(q, (1 << 32) - 1).astype(np.uint64)
    return np.lexsort((z_order(cells), ~ok))


@numba.njit(cache=True, nogil=True)
def z_order(cells):
    """The place of cells (N, 2) (uint64, each < 2^32) along a Z-order curve (uint64): their bits interleaved."""
    out = np.empty(len(cells), np.uint64)
    for i in range(len(cells)):
        out[i] = _z(cells[i, 0], cells[i, 1])
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _z(x, y):
    """The place of cell (x, y) (uint64, each < 2^32) along the Z-order curve."""
    return _spread(x) | (_spread(y) << np.uint64(1))


@numba.njit(cache=True, nogil=True)
def _spread(v):
    """The bits of v (< 2^32, uint64) moved to the even bit positions."""
    v = (v | (v << np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x3333333333333333)
    return (v | (v << np.uint64(1))) & np.uint64(0x5555555555555555)


def _frame_triangles(xy: np.ndarray, corners: np.ndarray | None, k: int) -> np.ndarray:
    """Frame k's triangles (P, 3, 2) of overlap_pairs' tracks: xy[k] itself, or without a copy of xy, its
    vertices xy[k] (V, 2) gathered by corners (P, 3)."""
    return np.take(xy[k], corners, axis=0) if corners is not None else xy[k]


def block_frames(xy_paths: np.ndarray, corners: np.ndarray | None = None, drift: np.ndarray | None = None) -> int:
    """Frames per candidate-search block for overlap_pairs' tracks: the median triangle's size (largest side of its
    box at frame 0) over the median distance a point moves in a frame (largest axis, less drift (T, 2) when
    given), within BLOCK_RANGE."""
    head = xy_paths[:MOTION_FRAMES + 1]
    if len(head) < 2:
        return BLOCK_RANGE[0]
    if drift is not None:
        head = head - _per_frame(drift[:len(head)], head.ndim)
    first = _frame_triangles(head, corners, 0)
    if not first.size:
        return BLOCK_RANGE[0]
    size = float(np.median((first.max(axis=1) - first.min(axis=1)).max(axis=1)))
    step = float(np.median(np.abs(np.diff(head, axis=0)).max(axis=-1)))
    ratio = size / step if step > 0 else np.inf
    if not np.isfinite(ratio):  # nothing moves (or the positions are not finite): the widest block
        return BLOCK_RANGE[1]
    return int(np.clip(round(ratio), *BLOCK_RANGE))


def _per_frame(drift: np.ndarray, ndim: int) -> np.ndarray:
    """drift (T, 2) shaped to broadcast against tracks of ndim dimensions (T, ..., 2)."""
    return np.asarray(drift).reshape((len(drift),) + (1,) * (ndim - 2) + (2,))


def overlap_pairs(xy_paths: np.ndarray, active: np.ndarray, block: int | None = None,
                  margin: float = STROKE_MARGIN_PX, band: np.ndarray | None = None,
                  corners: np.ndarray | None = None, drift: np.ndarray | None = None,
                  progress: Progress = no_progress) -> np.ndarray:
    """(E, 2) path pairs i < j that may come within margin px of each other in a frame where both are drawn.
    xy_paths (T, P, 3, 2) px, or with corners (P, 3) vertex ids into xy_paths (T, V, 2), gathered a block of
    frames at a time (no (T, P, 3, 2) copy).

    Candidates: per block of frames, pairs whose bounding boxes over the block's drawn frames (grown by
    margin / 2, the stroke's spill) meet, found through a uniform grid. Each candidate is then tested in the
    frames of the block where both are drawn: their boxes, then the separating-axis test (``apart``). A pair is
    kept unless every such frame shows it apart, so the result is conservative. A pair found in one block is not
    tested again. A negative margin asks for pairs whose interiors overlap by more than -margin along every axis
    (converter.encode.order). With band (P,), only pairs of different bands are returned (``reorder`` keeps each
    band's own order anyway). On the capture-like face this exact test removes many of the runs the box test alone
    leaves.
    block: frames per block (default ``block_frames``).

    drift (T, 2) px, optional: a translation per frame (the head's) taken off before the candidate search. A
    translation moves every box of a frame alike, so the same pairs come out; what the paths do besides it is
    slower, so a block spans more frames for the same box sizes (on the 128k-triangle bench face, taking off the
    head's translation lets a block span more frames than the screen alone allows).

    progress("overlap", fraction of the frames searched) after each block."""
    t, p = active.shape
    block = block_frames(xy_paths, corners, drift) if block is None else block
    xy32 = xy_paths if corners is not None else np.asarray(xy_paths, np.float32)
    m32 = np.float32(margin)
    grow = np.float32(margin / 2)
    if drift is not None and t:
        drift = np.asarray(drift, np.float64)
        # The float32 difference is rounded (half an ulp of the result, plus the drift's own rounding): the boxes
        # grow by that much more, so a pair within margin on screen still has meeting boxes.
        # fmax/fmin skip NaN (unset vertices) with no temporary of the tracks' size
        span = (float(np.fmax.reduce(xy32, axis=None)), -float(np.fmin.reduce(xy32, axis=None))) if xy32.size else (0,)
        reach = max(span) + float(np.abs(drift).max())
        if np.isfinite(reach):
            grow = np.float32(margin / 2 + 4 * np.finfo(np.float32).eps * reach)
        else:  # positions or drift not finite: searched on screen
            drift = None
    # Paths numbered along the screen (number i is path order[i]): a cell's paths and their pairs' PairSet tiles
    # are then near in memory.
    order = screen_order(_frame_triangles(xy32, corners, 0).mean(axis=1)) if t else np.arange(p)
    band = band[order] if band is not None else None
    found = PairSet(p)
    buffers: list[np.ndarray] = []  # _candidates' pairs, a buffer per thread, reused (and grown) block to block
    for k0 in range(0, t, block):
        progress("overlap", k0 / t)
        act = np.take(active[k0:k0 + block], order, axis=1)
        idx = np.flatnonzero(act.any(axis=0))
        if len(idx) < 2:
            continue
        if corners is None:
            pts = np.take(xy32[k0:k0 + block], order[idx], axis=1)  # (B, n, 3, 2)
        else:
            pts = np.asarray(np.take(xy32[k0:k0 + block], corners[order[idx]], axis=1), np.float32)
        on = np.take(act, idx, axis=1)
        seen = pts if drift is None else pts - _per_frame(drift[k0:k0 + block], pts.ndim).astype(np.float32)
        lo, hi = _boxes(seen, on, grow)
        del seen
        cell = max(CELL_BOXES * float(np.median((hi - lo).max(axis=1))), 1.0)
        own_band = band[idx] if band is not None else np.arange(len(idx))  # most neighbours share a band
        # Boxes over more than BIG_CELLS cells (a part blown up, a vertex near the eye plane) would take a grid entry
        # per cell (billions): they are paired with every box they meet directly instead, the others on the grid.
        small = np.flatnonzero(_cells_covered(lo, hi, cell) <= BIG_CELLS)
        if len(small) < len(idx):
            la, lb = _big_candidates(lo, hi, own_band, small, found, idx)
            _test(found, pts, on, idx, la, lb, m32)
            if len(small) < 2:
                continue
        else:
            small = None
        # Only pairs not found in an earlier block come back, to be tested. The cells are shared among the threads
        # (a slice of the entries each, each with a buffer of its own).
        cells = (_cell_lists(lo, hi, cell, own_band) if small is None
                 else _cell_lists(lo[small], hi[small], cell, own_band[small]))
        ids = idx if small is None else idx[small]
        parts = parallel.slices(len(cells[0]))
        buffers += [np.empty((p // len(parts) + 1, 2), np.int64) for _ in range(len(parts) - len(buffers))]
        got = parallel.run([partial(_candidates, *cells, ids, found.table, found.shift, found.tiles, buffers[i], a, b)
                            for i, (a, b) in enumerate(parts)])
        buffers[:len(got)] = [buf for buf, _ in got]
        for buf, m in got:  # each slice's candidates tested where they lie (no joined copy)
            la, lb = buf[:m, 0], buf[:m, 1]
            if small is not None:  # boxes of the grid -> the block's paths
                la, lb = small[la], small[lb]
            _test(found, pts, on, idx, la, lb, m32)
    return found.pairs(order)


def _test(found: PairSet, pts: np.ndarray, on: np.ndarray, idx: np.ndarray, la: np.ndarray, lb: np.ndarray,
          margin: np.float32) -> None:
    """Add to found the candidates (la[c] < lb[c], the block's paths idx) that come within margin in a frame of
    the block (pts, on) where both are drawn."""
    meet = np.zeros(len(la), bool)
    if len(la):
        parallel.threaded(_meet, len(la), pts, on, la, lb, margin, meet)
    found.add(idx[la[meet]], idx[lb[meet]])


def _cells_covered(lo: np.ndarray, hi: np.ndarray, cell: float) -> np.ndarray:
    """Per box [lo, hi] (N, 2), how many cells of side cell it covers (float64: it may be astronomical)."""
    span = np.floor(np.asarray(hi, np.float64) / cell) - np.floor(np.asarray(lo, np.float64) / cell) + 1
    return span[:, 0] * span[:, 1]


def _big_candidates(lo: np.ndarray, hi: np.ndarray, band: np.ndarray, small: np.ndarray, found: PairSet,
                    idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs (la < lb) with at least one box not in small: boxes that meet, of different bands, whose
    paths (idx) are not yet in found; what the grid would give for them, by direct box tests."""
    n = len(lo)
    big = np.setdiff1d(np.arange(n), small)
    out_a, out_b = [], []
    for s in range(0, len(big), BIG_CHUNK):
        b = big[s:s + BIG_CHUNK]
        meet = ((np.maximum(lo[b, None, 0], lo[None, :, 0]) <= np.minimum(hi[b, None, 0], hi[None, :, 0]))
                & (np.maximum(lo[b, None, 1], lo[None, :, 1]) <= np.minimum(hi[b, None, 1], hi[None, :, 1]))
                & (band[b, None] != band[None, :]))
        meet[:, big] &= big[None, :] > b[:, None]  # two big boxes: once, in the row of the first
        i, j = np.nonzero(meet)
        out_a.append(np.minimum(b[i], j))
        out_b.append(np.maximum(b[i], j))
    la, lb = (np.concatenate(out_a), np.concatenate(out_b)) if out_a else (np.zeros(0, np.int64),) * 2
    new = ~found.has(idx[la], idx[lb]) if len(la) else np.zeros(0, bool)
    return la[new], lb[new]
