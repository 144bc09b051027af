"""A triangle-id rasteriser for the occlusion pass: GL's rules without multisampling, compiled, on the CPU.

Which triangle is nearest at each pixel centre of a frame, as GL draws it with a depth test (GL_LESS, depth
cleared to the far plane, near and far clipping, back faces culled): window positions snapped to a 1/256 px
grid as GL rasterisers do (Mesa's llvmpipe among them), then exact integer edge functions with the top-left rule,
so a pixel centre on an edge two triangles share belongs to exactly one of them. The depth is the triangle's
plane at the pixel centre, in float64.

Why not GL itself (Mesa's llvmpipe, which this pass used): a face's triangles are a few pixels each, and
llvmpipe's per-triangle setup and binning dominate its frame, the draw call and the rasterisation alike; here
a frame's draw costs a fraction of that, the more so on dense faces (bench_occlusion times the pass). The GL
renderer stays as the tests' independent reference (tests/reference/gl_ids.py): the two draw the same ids on
every pixel of the faces tested (float32 window positions snapped as GL snaps them) except where two surfaces
lie within float32 depth rounding of each other, on rare pixels of dense faces.
"""

from __future__ import annotations

import numba
import numpy as np

SUBPIXEL = 256  # sub-pixel grid of the snapped positions (8 bits, as llvmpipe's)
LIMIT = float(1 << 21)  # px: beyond this a corner's snapped products could overflow int64; such triangles (a
# corner almost in the eye plane) are rasterised in float64 instead
FAR = np.int64(-(1 << 62))  # window_positions' mark of a corner beyond LIMIT (or not finite)
WHOLE = 1 << 30  # px: a tile side past any frame's size, so that ALL_TILES (one tile, marked) is the whole frame
ALL_TILES = np.ones((1, 1), np.bool_)  # (writable, so that it shares the id pass's compiled signature: not to be
# written)


@numba.njit(cache=True, nogil=True, inline="always")
def depth_slope(xy, z, i0, i1, i2):
    """The depth slope (per pixel x, y) of the triangle of vertices i0, i1, i2; 0 (or nan) when degenerate."""
    e1x, e1y = xy[i1, 0] - xy[i0, 0], xy[i1, 1] - xy[i0, 1]
    e2x, e2y = xy[i2, 0] - xy[i0, 0], xy[i2, 1] - xy[i0, 1]
    d1, d2 = z[i1] - z[i0], z[i2] - z[i0]
    det = e1x * e2y - e1y * e2x
    safe = det if abs(det) > 1e-12 else np.inf
    return (d1 * e2y - d2 * e1y) / safe, (d2 * e1x - d1 * e2x) / safe


@numba.njit(cache=True, nogil=True, inline="always")
def _bias(dx, dy) -> int:
    """0 for a left or (y down) bottom edge, whose pixel centres are inside, 1 otherwise; inside where E < 0. GL's
    window y points up, so this is the top-left rule there (Mesa's choice, measured against llvmpipe)."""
    return 0 if dy > 0 or (dy == 0 and dx > 0) else 1


@numba.njit(cache=True, nogil=True, inline="always")
def _meets(tiles, tile, c_lo, c_hi, r_lo, r_hi) -> bool:
    """Whether the pixels c_lo..c_hi x r_lo..r_hi (within the frame) meet a marked tile of tiles (tile px a side)."""
    for tr in range(r_lo // tile, r_hi // tile + 1):
        for tc in range(c_lo // tile, c_hi // tile + 1):
            if tiles[tr, tc]:
                return True
    return False


@numba.njit(cache=True, nogil=True)
def draw_ids(fixed, xy, z, faces, drawn, ids, depth, tiles, tile) -> None:
    """Rasterise faces f with drawn[f] (in face order: on equal depth the first drawn stays) into ids (H, W;
    f + 1, 0 background, row 0 at the top) and depth (H, W; NDC), both cleared here. fixed (V, 2) int64 is the
    corners snapped to 1/SUBPIXEL px with y down (window_positions), xy (V, 2) float64 the same unsnapped, z (V,)
    NDC depth; a face is front-facing when counter-clockwise in GL, clockwise here.

    Only the tiles asked for are drawn right: tiles (H / tile, W / tile rounded up) bool marks the square tiles of
    tile px whose pixels are wanted, and a face none of whose pixel centres' box meets such a tile is skipped (every
    face covering a pixel of a marked tile is drawn, in order, so those pixels are what the whole draw gives them;
    the others are left as they come). ALL_TILES with a tile of WHOLE asks for every pixel."""
    h, w = ids.shape
    ids[:] = 0
    depth[:] = 1.0
    s = SUBPIXEL
    half = SUBPIXEL // 2
    for f in range(faces.shape[0]):
        if not drawn[f]:
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0 = fixed[i0, 0], fixed[i0, 1]
        x1, y1 = fixed[i1, 0], fixed[i1, 1]
        x2, y2 = fixed[i2, 0], fixed[i2, 1]
        if x0 == FAR or x1 == FAR or x2 == FAR:
            _draw_float(xy, z, i0, i1, i2, f, ids, depth)
            continue
        c_lo = max(0, -((half - min(x0, x1, x2)) // s))  # the first column whose centre is >= the leftmost corner
        c_hi = min(w - 1, (max(x0, x1, x2) - half) // s)
        r_lo = max(0, -((half - min(y0, y1, y2)) // s))
        r_hi = min(h - 1, (max(y0, y1, y2) - half) // s)
        if c_lo > c_hi or r_lo > r_hi:
            continue  # no pixel centre in its box (most sub-pixel triangles)
        if not _meets(tiles, tile, c_lo, c_hi, r_lo, r_hi):
            continue
        if (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0) >= 0:
            continue  # back-facing or degenerate once snapped, as GL culls it
        gx, gy = depth_slope(xy, z, i0, i1, i2)
        # E_i(P) = dx_i (Py - y_i) - dy_i (Px - x_i) over the edges i -> i + 1; inside: E_i + bias_i <= 0 for all.
        dx0, dy0, dx1, dy1, dx2, dy2 = x1 - x0, y1 - y0, x2 - x1, y2 - y1, x0 - x2, y0 - y2
        b0, b1, b2 = _bias(dx0, dy0), _bias(dx1, dy1), _bias(dx2, dy2)
        px, py = c_lo * s + half, r_lo * s + half
        e0 = dx0 * (py - y0) - dy0 * (px - x0) + b0
        e1 = dx1 * (py - y1) - dy1 * (px - x1) + b1
        e2 = dx2 * (py - y2) - dy2 * (px - x2) + b2
        zx = xy[i0, 0]
        zy = xy[i0, 1]
        zr = z[i0] + ((c_lo + 0.5 - zx) * gx + (r_lo + 0.5 - zy) * gy)
        for r in range(r_lo, r_hi + 1):
            f0, f1, f2, zc = e0, e1, e2, zr
            entered = False
            for c in range(c_lo, c_hi + 1):
                if f0 <= 0 and f1 <= 0 and f2 <= 0:
                    entered = True
                    if -1.0 <= zc < depth[r, c]:
                        depth[r, c] = zc
                        ids[r, c] = f + 1
                elif entered:
                    break  # a row's inside is one run (the triangle is convex)
                f0 -= dy0 * s
                f1 -= dy1 * s
                f2 -= dy2 * s
                zc += gx
            e0 += dx0 * s
            e1 += dx1 * s
            e2 += dx2 * s
            zr += gy


@numba.njit(cache=True, nogil=True)
def _draw_float(xy, z, i0, i1, i2, f, ids, depth) -> None:
    """draw_ids for one triangle with a corner beyond LIMIT: unsnapped float64 edges over the viewport's part of
    its box (no exact tie rule: a corner that far is a camera almost inside the mesh)."""
    h, w = ids.shape
    x0, y0, x1, y1, x2, y2 = xy[i0, 0], xy[i0, 1], xy[i1, 0], xy[i1, 1], xy[i2, 0], xy[i2, 1]
    if not (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0) < 0:
        return  # back-facing, degenerate or not finite
    if not (max(x0, x1, x2) > -1.0 and min(x0, x1, x2) < w + 1.0 and max(y0, y1, y2) > -1.0
            and min(y0, y1, y2) < h + 1.0):
        return
    gx, gy = depth_slope(xy, z, i0, i1, i2)
    c_lo = max(0, int(np.ceil(min(x0, x1, x2) - 0.5)))
    c_hi = min(w - 1, int(np.floor(max(x0, x1, x2) - 0.5)))
    r_lo = max(0, int(np.ceil(min(y0, y1, y2) - 0.5)))
    r_hi = min(h - 1, int(np.floor(max(y0, y1, y2) - 0.5)))
    for r in range(r_lo, r_hi + 1):
        py = r + 0.5
        for c in range(c_lo, c_hi + 1):
            px = c + 0.5
            if ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0) <= 0
                    and (x2 - x1) * (py - y1) - (y2 - y1) * (px - x1) <= 0
                    and (x0 - x2) * (py - y2) - (y0 - y2) * (px - x2) <= 0):
                zc = z[i0] + ((px - x0) * gx + (py - y0) * gy)
                if -1.0 <= zc < depth[r, c]:
                    depth[r, c] = zc
                    ids[r, c] = f + 1


@numba.njit(cache=True, nogil=True, error_model="numpy")  # a corner in the eye plane divides by 0: inf, no raise
def window_positions(points, m, width, height, fixed, xy, z) -> None:
    """Project points (V, 3) by m (4, 4, world to clip) into fixed (V, 2; int64, 1/SUBPIXEL px, y down, as GL
    snaps its float32 window positions), xy (V, 2; float64 px, y down) and z (V,; NDC depth)."""
    half_w, half_h = np.float32(width / 2), np.float32(height / 2)
    one, s = np.float32(1.0), np.float32(SUBPIXEL)
    for i in range(points.shape[0]):
        x, y, zz = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        # float32 clip coordinates, as GL receives them
        cx = np.float32(x * m[0, 0] + y * m[0, 1] + zz * m[0, 2] + m[0, 3])
        cy = np.float32(x * m[1, 0] + y * m[1, 1] + zz * m[1, 2] + m[1, 3])
        cz = np.float32(x * m[2, 0] + y * m[2, 1] + zz * m[2, 2] + m[2, 3])
        cw = np.float32(x * m[3, 0] + y * m[3, 1] + zz * m[3, 2] + m[3, 3])
        wd = np.float64(cw)
        xy[i, 0] = (cx / wd + 1) * 0.5 * width
        xy[i, 1] = (1 - cy / wd) * 0.5 * height
        z[i] = cz / wd
        r = one / cw
        wx = cx * r * half_w + half_w
        wy = cy * r * half_h + half_h
        if abs(wx) < LIMIT and abs(wy) < LIMIT:
            fixed[i, 0] = np.int64(np.rint(wx * s))
            fixed[i, 1] = height * SUBPIXEL - np.int64(np.rint(wy * s))
        else:
            fixed[i, 0], fixed[i, 1] = FAR, FAR  # draw_ids rasterises such a corner's triangles from xy
