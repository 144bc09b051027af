"""The occlusion pass: which triangles are ever seen, from one small integer-id render per frame.

Each frame's ids are rasterised on the CPU by converter.raster, GL's rules without multisampling (it agrees
with Mesa's llvmpipe on every pixel of the bench faces but depth ties below float32 rounding, and keeps the same
triangles; the tests check it against that GL render), into an id and a depth buffer reused for every frame; a
compiled loop marks the ids' faces. A frame is drawn and read only in the tiles around the triangles it may
still add (those it draws that no earlier frame kept), which cuts the pass's CPU; on the ICT head rule 2's
probes of its thousands of hidden sub-pixel triangles a frame are most of what is left (bench_occlusion times the
pass: BENCHMARKS.md, occlusion pass). Frames are split between parallel.THREADS slots. GL (llvmpipe) drew the ids
before: its per-triangle setup made the draw of a dense face's frame cost several times what the whole frame, rule
2 included, costs here (converter.raster).

A frame draws only the triangles the SVG draws in it (front-facing, in the view: converter.extract.cull), as
the writers hide the others there: a triangle culled in a frame hides nothing in it (one with a corner behind
the eye would otherwise hide what is behind its near part).

The rule (issue 15.8), in two parts:

1. Pixel centres. A triangle that is front-facing and owns a pixel centre at the working resolution in some
   frame (nearest drawn face there, GL's rasterisation rule without multisampling) is kept, however small.
   Ids are exact integers, so no blend of two ids can stand for a third triangle or hide a small one.
2. Sub-pixel triangles. A front-facing, in-frustum triangle whose inscribed circle is narrower than a pixel
   diagonal (inradius < sqrt(2)/2 px, the only triangles that can miss every pixel centre) and that owns no
   pixel centre in a frame still shows in an anti-aliased SVG as a fraction of a pixel; dropping it leaves a
   light speckle where the surface has no other triangle. It is kept when it is not behind the visible
   surface at one of four probe points p inside it (its centroid, and each corner moved 10% toward the
   centroid, so that a triangle whose middle is covered but whose tip peeks out counts): the pixel holding p
   is empty, or the plane of that pixel's owner, evaluated at p, is not nearer than the triangle by more
   than the two planes can part over the distance d from p to the owner's pixel centre
   (2 |slope_t - slope_owner| d, plus float rounding). A triangle of the same surface passes (its plane and
   the owner's meet within d); one strictly behind another surface (an inner mouth behind the lips, an
   eyeball behind a closed lid) is farther by a gap and is dropped.
   Why not ids at a higher resolution: it only moves the limit (a triangle smaller than the finer pixel
   still slips) and a 3x render costs several times the frame. The probe rule errs on the safe side: where the
   owner is steep (lip and lid
   margins) it keeps hidden sub-pixel triangles just behind, which cost bytes, never a hole; what it can
   miss is a sub-pixel triangle covered at all four probes while a sliver of it peeks out (on the dense
   ICT head a few pixels of summed coverage a frame, far less than the old pass lost: BENCHMARKS.md, occlusion
   pass).
"""

from __future__ import annotations

import numba
import numpy as np

from converter import raster
from converter.camera import Camera
from converter.encode import parallel

INRADIUS_PX = 0.5 ** 0.5  # a triangle whose inscribed circle is this wide holds a pixel centre
SLACK = 2.0  # margin on the depth two planes of one surface can part by between the centroid and the pixel centre
DEPTH_EPS = 1e-6  # NDC depth below which two surfaces count as one (float rounding)
PROBE_IN = 0.1  # corner probes sit this far from each corner toward the centroid, inside the triangle

TILE = 16  # px: a frame is drawn only in the tiles of this side that hold a triangle not yet kept (a small part of
# the screen after the first frames)
TILE_MARGIN = 2  # px around such a triangle's box: its pixel centres and its probes' pixels lie well within
CHUNK = 16  # frames per slot between progress reports
SLOT_BUDGET = 64 << 20  # bytes the slots' buffers may take together, unless one slot needs more: a large --size
# renders on one thread (at 8192 px one slot takes 805 MB, as llvmpipe's id and depth targets and read-back ids did)


def ever_seen(frames: np.ndarray, faces: np.ndarray, camera: Camera, visible: np.ndarray,
              progress=None) -> np.ndarray:
    """Bool (F,): the triangles some frame shows by the module's rule; visible (T, F) is the culling. Frames are
    split among up to parallel.THREADS slots, each with its own id and depth buffers (SLOT_BUDGET)."""
    t, f, v = visible.shape[0], faces.shape[0], frames.shape[1]
    h, w = camera.height, camera.width
    slots = max(1, min(parallel.THREADS, t, SLOT_BUDGET // (h * w * 12 + v * 40)))
    kept = np.zeros((slots, f), bool)
    ids, depth = np.empty((slots, h, w), np.uint32), np.empty((slots, h, w))
    fixed, xy, z = np.empty((slots, v, 2), np.int64), np.empty((slots, v, 2)), np.empty((slots, v))
    tiles = np.empty((slots, -(-h // TILE), -(-w // TILE)), np.bool_)
    m = np.ascontiguousarray(camera.projection @ camera.view, np.float64)
    if frames.flags.writeable:  # a still's frame, copied out of the animation's (read-only) frames
        frames = frames.view()
        frames.flags.writeable = False  # so that _frames has one signature (warm.py compiles it ahead)
    faces64 = np.ascontiguousarray(faces, np.int64)
    visible = np.ascontiguousarray(visible, np.bool_)
    for a in range(0, t, CHUNK * slots):
        b = min(t, a + CHUNK * slots)
        parallel.threaded(_frames, slots, frames, m, faces64, visible, w, h, a, b, kept, ids, depth, fixed, xy, z,
                          tiles, TILE)
        if progress:
            progress(b / t)
    return kept.any(axis=0)


@numba.njit(cache=True, nogil=True)
def _frames(frames, m, faces, visible, width, height, a, b, kept, ids, depth, fixed, xy, z, tiles, tile, first,
            stop):
    """ever_seen's frames a..b-1 for slots first..stop-1 (slot i takes the i-th of kept.shape[0] equal parts),
    into the slot's kept row, with its buffers.

    A frame can only add triangles it draws that are not kept yet, and whether it does depends only on the ids at
    their pixels (their own, and at rule 2's probes): so it is drawn and read in the tiles around those triangles
    alone (raster.draw_ids' tiles), and not at all when there are none. The kept set is the whole frames'."""
    slots = kept.shape[0]
    for slot in range(first, stop):
        for k in range(a + (b - a) * slot // slots, a + (b - a) * (slot + 1) // slots):
            raster.window_positions(frames[k], m, width, height, fixed[slot], xy[slot], z[slot])
            if not candidate_tiles(xy[slot], fixed[slot], faces, visible[k], kept[slot], tiles[slot], tile):
                continue
            raster.draw_ids(fixed[slot], xy[slot], z[slot], faces, visible[k], ids[slot], depth[slot], tiles[slot],
                            tile)
            _mark(ids[slot], visible[k], kept[slot], tiles[slot], tile)
            for face in range(faces.shape[0]):
                if visible[k, face] and not kept[slot, face]:  # a front-facing triangle owns no pixel centre: rule 2
                    _subpixel(ids[slot], xy[slot], z[slot], faces, visible[k], kept[slot])
                    break


@numba.njit(cache=True, nogil=True)
def candidate_tiles(xy, fixed, faces, visible, kept, tiles, tile) -> bool:
    """Mark in tiles (bool, tiles of tile px a side) those within TILE_MARGIN px of a visible face not yet kept
    (every tile when such a face has a corner not finite or beyond raster.LIMIT): whether there is such a face. xy
    (V, 2) px and fixed (V, 2) as raster.window_positions gives them."""
    tiles[:] = False
    th, tw = tiles.shape
    h, w = th * tile, tw * tile
    found = False
    for f in range(faces.shape[0]):
        if not visible[f] or kept[f]:
            continue
        found = True
        x_lo, x_hi, y_lo, y_hi = np.inf, -np.inf, np.inf, -np.inf
        for c in range(3):
            i = faces[f, c]
            if fixed[i, 0] == raster.FAR or not (np.isfinite(xy[i, 0]) and np.isfinite(xy[i, 1])):
                tiles[:] = True
                return True
            x_lo, x_hi = min(x_lo, xy[i, 0]), max(x_hi, xy[i, 0])
            y_lo, y_hi = min(y_lo, xy[i, 1]), max(y_hi, xy[i, 1])
        # Pixels clamped into the frame, as rule 2 clamps a probe's pixel
        c0 = min(max(np.floor(x_lo) - TILE_MARGIN, 0.0), w - 1.0)
        c1 = min(max(np.floor(x_hi) + TILE_MARGIN, 0.0), w - 1.0)
        r0 = min(max(np.floor(y_lo) - TILE_MARGIN, 0.0), h - 1.0)
        r1 = min(max(np.floor(y_hi) + TILE_MARGIN, 0.0), h - 1.0)
        for tr in range(int(r0) // tile, int(r1) // tile + 1):
            for tc in range(int(c0) // tile, int(c1) // tile + 1):
                tiles[tr, tc] = True
    return found


@numba.njit(cache=True, nogil=True)
def _mark(ids, visible, kept, tiles, tile):
    """kept[f] = True for each face f that owns a pixel of ids (H, W; f + 1, 0 the background) in a marked tile
    (tiles, tile px a side) and is visible: one pass over those ids (marking a flag array through
    ids.astype(intp) cost a whole frame's conversion every frame)."""
    n = kept.shape[0]
    h, w = ids.shape
    for tr in range(tiles.shape[0]):
        for tc in range(tiles.shape[1]):
            if not tiles[tr, tc]:
                continue
            for i in range(tr * tile, min((tr + 1) * tile, h)):
                for j in range(tc * tile, min((tc + 1) * tile, w)):
                    v = ids[i, j]
                    if 0 < v <= n and visible[v - 1]:
                        kept[v - 1] = True


@numba.njit(cache=True, nogil=True)
def _subpixel(ids, xy, z, faces, visible, kept):
    """Rule 2 of the module docstring, in place: kept[f] = True for each visible face f not yet kept whose
    inscribed circle is narrower than INRADIUS_PX and which is not behind the visible surface at one of its probe
    points. ids (H, W) as raster.draw_ids draws them; xy (V, 2) pixels with y down and z (V,) NDC depth of the
    same frame. Compiled: as numpy over each frame's few candidates its cost was mostly call overhead. The
    arithmetic is numpy's, operation for operation (tests/core/test_occlusion.py keeps that version)."""
    owner = np.empty(3)
    for f in range(len(kept)):
        if kept[f] or not visible[f]:
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y = xy[i1, 0] - xy[i0, 0], xy[i1, 1] - xy[i0, 1]
        e2x, e2y = xy[i2, 0] - xy[i0, 0], xy[i2, 1] - xy[i0, 1]
        ax, ay = xy[i1, 0] - xy[i2, 0], xy[i1, 1] - xy[i2, 1]
        perimeter = np.sqrt(ax * ax + ay * ay) + np.sqrt(e2x * e2x + e2y * e2y) + np.sqrt(e1x * e1x + e1y * e1y)
        if not abs(e1x * e2y - e1y * e2x) / max(perimeter, 1e-12) < INRADIUS_PX:  # inscribed circle's radius
            continue
        cx = (xy[i0, 0] + xy[i1, 0] + xy[i2, 0]) / 3
        cy = (xy[i0, 1] + xy[i1, 1] + xy[i2, 1]) / 3
        gx, gy = raster.depth_slope(xy, z, i0, i1, i2)
        owner[0] = -1  # the owner whose slope owner[1:] holds: a sub-pixel triangle's probes mostly share one
        for probe in range(4):
            if probe == 0:
                px, py = cx, cy
            else:
                v = faces[f, probe - 1]
                px, py = PROBE_IN * cx + (1 - PROBE_IN) * xy[v, 0], PROBE_IN * cy + (1 - PROBE_IN) * xy[v, 1]
            if _in_front(ids, xy, z, faces, px, py, z[i0], xy[i0, 0], xy[i0, 1], gx, gy, owner):
                kept[f] = True
                break


@numba.njit(cache=True, nogil=True, inline="always")
def _in_front(ids, xy, z, faces, px, py, z0, x0, y0, gx, gy, cache) -> bool:
    """The plane (depth z0 at (x0, y0), slope (gx, gy)) is not behind the owner of the pixel holding (px, py).
    cache (3,): the last owner met and its slope, reused when the pixel has the same owner."""
    h, w = ids.shape
    col = min(max(np.int64(np.floor(px)), 0), w - 1)
    row = min(max(np.int64(np.floor(py)), 0), h - 1)
    owner = np.int64(ids[row, col]) - 1
    if owner < 0:
        return True
    o0, o1, o2 = faces[owner, 0], faces[owner, 1], faces[owner, 2]
    if cache[0] != owner:
        cache[1], cache[2] = raster.depth_slope(xy, z, o0, o1, o2)
        cache[0] = owner
    ox, oy = cache[1], cache[2]
    z_t = z0 + ((px - x0) * gx + (py - y0) * gy)
    z_o = z[o0] + ((px - xy[o0, 0]) * ox + (py - xy[o0, 1]) * oy)
    rx, ry = px - col - 0.5, py - row - 0.5
    dx, dy = gx - ox, gy - oy
    if np.isfinite(dx) and np.isfinite(dy):
        # Then tol below lies between DEPTH_EPS and this bound (|a| + |b| >= hypot(a, b); the factor covers
        # rounding): a probe clearly in front or clearly behind is decided without hypot and sqrt, which the hidden
        # sub-pixel triangles of a dense face meet every frame.
        if z_t <= z_o + DEPTH_EPS:
            return True
        if z_t > z_o + (SLACK * (abs(dx) + abs(dy)) * (abs(rx) + abs(ry)) * (1 + 1e-9) + DEPTH_EPS):
            return False
    reach = np.hypot(rx, ry)
    tol = SLACK * np.sqrt(dx * dx + dy * dy) * reach + DEPTH_EPS
    return z_t <= z_o + tol
