"""2D extraction (the chapter's 'Extraction of 2D Data'): projection, culling, occlusion, shading, order."""

from __future__ import annotations

import numba
import numpy as np

from converter import framing, idpass, render
from converter.animation import FaceAnimation
from converter.arrays import painter_order
from converter.camera import Camera
from converter.errors import InputError
from converter.lighting import DEFAULT_LIGHTING, Lighting, lambert_linear, srgb_to_linear
from converter.options import Progress, no_progress
from converter.sheet import Sheet

FRAME_BLOCK = 8  # frames per block of the per-frame work (every result is per frame, so blocks change no byte).
# Small enough that a block's float64 temporaries are reused memory: at 32 frames each was a fresh mapping the
# kernel zeroed (on the 128k-triangle face, page faults and system CPU in extraction)


def fit_camera(anim: FaceAnimation, size: int = 512, yaw: float = 0.0, pitch: float = 0.0,
               fov: float = 30.0, ortho: bool = False, frame_on: str | None = None) -> Camera:
    """The camera that frames the animation (every frame) from the chosen angle: see framing.resolve for what."""
    framed = framing.resolve(anim, frame_on)
    frames = anim.frames if framed.vertices is None else anim.frames[:, framed.vertices]  # a mask: not np.take
    return Camera.fit(frames, size=size, yaw=yaw + framed.yaw, pitch=pitch, fov=fov, ortho=ortho)


def cull(xy: np.ndarray, ndc_z: np.ndarray, w: np.ndarray, faces: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bool (T, F): whole-triangle view-frustum culling plus back-face culling (front = counter-clockwise in GL).

    A triangle is outside when its three corners lie beyond one side of the view volume, behind when one corner
    is not in front of the eye (w <= 0). Compiled, one pass per frame over its vertices (a bit per side) and one
    over its faces: as numpy's gathers and passes over (T, F) arrays it was one of extraction's largest costs on
    dense faces and long captures. The arithmetic is numpy's, operation for operation (tests/core/test_camera.py
    keeps that version)."""
    lead = ndc_z.shape[:-1]
    v = ndc_z.shape[-1]
    out = np.empty(lead + (len(faces),), bool)
    _cull(np.ascontiguousarray(xy).reshape(-1, v, 2), np.ascontiguousarray(ndc_z).reshape(-1, v),
          np.ascontiguousarray(w).reshape(-1, v), np.ascontiguousarray(faces, np.int64), width, height,
          out.reshape(-1, len(faces)))
    return out


@numba.njit(cache=True, nogil=True)
def _cull(xy, ndc_z, w, faces, width, height, out):
    """cull() of frames (T, V) into out (T, F)."""
    bits = np.empty(ndc_z.shape[1], np.uint8)
    for k in range(ndc_z.shape[0]):
        for i in range(ndc_z.shape[1]):
            x, y, z = xy[k, i, 0], xy[k, i, 1], ndc_z[k, i]
            b = (x < 0) | (x > width) << 1 | (y < 0) << 2 | (y > height) << 3 | (z < -1) << 4 | (z > 1) << 5
            bits[i] = b | (not w[k, i] > 0) << 7
        for f in range(faces.shape[0]):
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            ax, ay = xy[k, i0, 0], xy[k, i0, 1]
            # Screen y points down, so a counter-clockwise (front) triangle has a negative signed area here.
            area2 = (xy[k, i1, 0] - ax) * (xy[k, i2, 1] - ay) - (xy[k, i1, 1] - ay) * (xy[k, i2, 0] - ax)
            outside = (bits[i0] & bits[i1] & bits[i2] & 63) != 0
            behind = ((bits[i0] | bits[i1] | bits[i2]) & 128) != 0
            out[k, f] = area2 < 0 and not behind and not outside


def unit_face_normals(frames: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """animation.face_normals(frames, faces), the same bits, compiled: one pass with no (T, F, 3) temporaries
    (numpy's gathers, cross product and norm were a large share of extraction)."""
    out = np.empty((frames.shape[0], faces.shape[0], 3), np.float32)
    frames = np.ascontiguousarray(frames)
    _unit_face_normals(frames, np.ascontiguousarray(faces, np.int64), frames.dtype.type(1), out)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _cross(frames, faces, k, f):
    """Triangle f's (b - a) x (c - a) at frame k, in frames' precision, as numpy's cross: products, then
    differences (numba contracts nothing into FMAs without fastmath)."""
    i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
    ax = frames[k, i1, 0] - frames[k, i0, 0]
    ay = frames[k, i1, 1] - frames[k, i0, 1]
    az = frames[k, i1, 2] - frames[k, i0, 2]
    bx = frames[k, i2, 0] - frames[k, i0, 0]
    by = frames[k, i2, 1] - frames[k, i0, 1]
    bz = frames[k, i2, 2] - frames[k, i0, 2]
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@numba.njit(cache=True, nogil=True)
def _unit_face_normals(frames, faces, one, out):
    """unit_face_normals into out (T, F, 3), in frames' precision (one: 1 of it), operation for operation as
    numpy's: _cross, the sum of squares left to right, a zero or NaN length divided by as 1."""
    for k in range(frames.shape[0]):
        for f in range(faces.shape[0]):
            nx, ny, nz = _cross(frames, faces, k, f)
            ln = np.sqrt(nx * nx + ny * ny + nz * nz)
            if not ln > 0:
                ln = one
            out[k, f, 0] = nx / ln
            out[k, f, 1] = ny / ln
            out[k, f, 2] = nz / ln


def unit_vertex_normals(frames: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """animation.vertex_normals(frames, faces), the same bits, compiled (as numpy, a large share of every Gouraud
    conversion's extraction; one frame's sums at a time here)."""
    frames = np.ascontiguousarray(frames)
    out = np.empty((frames.shape[0], frames.shape[1], 3), np.float32)
    _unit_vertex_normals(frames, np.ascontiguousarray(faces, np.int64), out)
    return out


@numba.njit(cache=True, nogil=True)
def _unit_vertex_normals(frames, faces, out):
    """unit_vertex_normals into out (T, V, 3), as numpy sums: per frame, the area-weighted face normals (_cross,
    rounded to float32) added in float64 corner by corner (all faces' first corners in face order, then the second,
    then the third, each corner's sums added to the total), then divided by the length (1 where not > 0)."""
    t, v, f = frames.shape[0], frames.shape[1], faces.shape[0]
    fn = np.empty((f, 3), np.float32)
    total = np.empty((v, 3))
    corner = np.empty((v, 3))
    for k in range(t):
        for i in range(f):
            fn[i, 0], fn[i, 1], fn[i, 2] = _cross(frames, faces, k, i)
        total[:] = 0.0
        for c in range(3):
            corner[:] = 0.0
            for i in range(f):
                a = faces[i, c]
                corner[a, 0] += np.float64(fn[i, 0])
                corner[a, 1] += np.float64(fn[i, 1])
                corner[a, 2] += np.float64(fn[i, 2])
            for a in range(v):
                total[a, 0] += corner[a, 0]
                total[a, 1] += corner[a, 1]
                total[a, 2] += corner[a, 2]
        for a in range(v):
            x, y, z = total[a, 0], total[a, 1], total[a, 2]
            ln = np.sqrt(x * x + y * y + z * z)
            if not ln > 0:
                ln = 1.0
            out[k, a, 0] = x / ln
            out[k, a, 1] = y / ln
            out[k, a, 2] = z / ln


def _blocks(n_frames: int) -> list[slice]:
    """Frame blocks for projection, culling and shading: their float64 temporaries scale with a block, not the clip."""
    return [slice(s, min(s + FRAME_BLOCK, n_frames)) for s in range(0, n_frames, FRAME_BLOCK)]


def extract(
    anim: FaceAnimation,
    camera: Camera,
    neutral: int = 0,
    occlusion: bool = True,
    reference_frames: tuple[int, ...] = (),
    lighting: Lighting = DEFAULT_LIGHTING,
    progress: Progress = no_progress,
    occlusion_frames: tuple[int, ...] | None = None,
    vertex_colors: bool = True,
) -> Sheet:
    """Project every frame, cull, find never-seen triangles, shade, order: the Sheet writers read.

    vertex_colors=False leaves the per-vertex (Gouraud) colours out (Sheet.vertex_rgb None): flat outputs never
    read them, and on a long capture they are (T, V, 3) float32.

    occlusion_frames: the frames whose id renders decide which triangles are ever seen (default: all; a still
    needs only its own frame)."""
    if not (0 <= neutral < anim.n_frames):
        raise InputError(f"neutral frame {neutral} is outside 0..{anim.n_frames - 1}; choose one inside.")
    frames, faces = anim.frames, anim.faces
    t, v, f = anim.n_frames, anim.n_vertices, anim.n_faces
    xy, depth, visible = np.empty((t, v, 2), np.float32), np.empty((t, v), np.float32), np.empty((t, f), bool)
    for blk in _blocks(t):
        bxy, bz, bw = camera.project(frames[blk])
        visible[blk] = cull(bxy, bz, bw, faces, camera.width, camera.height)
        xy[blk], depth[blk] = bxy, bz
    progress("project", 0.1)
    if occlusion:
        sel = slice(None) if occlusion_frames is None else np.asarray(occlusion_frames, np.int64)
        kept = idpass.ever_seen(frames[sel], faces, camera, visible[sel],
                                progress=lambda f: progress("occlusion", 0.1 + 0.6 * f))
    else:
        kept = visible.any(axis=0)
    progress("shade", 0.75)
    vertex_colors = vertex_colors or bool(reference_frames)  # the reference renders are Gouraud-shaded
    # Only the kept triangles' colours are stored and lit (no writer draws the others, a large share on the ICT head);
    # n.l is worked out for every face, as before, then taken, so that each value keeps its bits
    kept_ids = np.flatnonzero(kept)
    face_rgb = np.empty((t, len(kept_ids), 3), np.float32)
    vertex_rgb = np.empty((t, v, 3), np.float32) if vertex_colors else None
    # decoded once, not per block of frames (a long capture has hundreds of blocks)
    tri_linear = np.take(srgb_to_linear(anim.triangle_colors()[None]), kept_ids, axis=1)
    vert_linear = srgb_to_linear(anim.face_base_colors()[None]) if vertex_rgb is not None else None
    for blk in _blocks(t):
        face_rgb[blk] = lambert_linear(unit_face_normals(frames[blk], faces), tri_linear, camera.view, lighting,
                                       rows=kept_ids)
        if vertex_rgb is not None:
            vertex_rgb[blk] = lambert_linear(unit_vertex_normals(frames[blk], faces), vert_linear, camera.view,
                                             lighting)
    _, neutral_z, _ = camera.project(frames[neutral:neutral + 1])  # float64: the order must not see rounding
    order = painter_order(neutral_z, faces, np.flatnonzero(kept), 0)
    refs = {}
    if reference_frames:
        bad = [k for k in reference_frames if not 0 <= k < anim.n_frames]
        if bad:
            raise InputError(f"reference frame {bad[0]} is outside 0..{anim.n_frames - 1}.")
        refs = render.render_frames(frames, faces, vertex_rgb, camera, list(reference_frames))
    progress("extract", 0.9)
    info = {
        "frames": anim.n_frames,
        "vertices": anim.n_vertices,
        "triangles": anim.n_faces,
        "triangles_kept": int(kept.sum()),
        "triangles_never_visible": int(anim.n_faces - kept.sum()),
    }
    return Sheet(
        camera=camera,
        fps=anim.fps,
        xy=xy,
        depth=depth,
        faces=faces,
        visible=visible,
        kept=kept,
        order=order,
        face_rgb=face_rgb,
        vertex_rgb=vertex_rgb,
        part_ids=anim.part_ids,
        part_names=tuple(p.name for p in anim.parts),
        neutral=neutral,
        name=anim.name,
        references=refs,
        info=info,
    )
