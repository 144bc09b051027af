"""2D extraction (the chapter's 'Extraction of 2D Data'): projection, culling, occlusion, shading, order."""

from __future__ import annotations

import numpy as np

from converter import framing, idpass, render
from converter.animation import FaceAnimation, face_normals, vertex_normals
from converter.camera import Camera
from converter.errors import InputError
from converter.lighting import DEFAULT_LIGHTING, Lighting, lambert
from converter.options import Progress, no_progress
from converter.sheet import Sheet

FRAME_BLOCK = 32  # frames per block of the per-frame work (every result is per frame, so blocks change no byte)


def fit_camera(anim: FaceAnimation, size: int = 512, yaw: float = 0.0, pitch: float = 0.0,
               fov: float = 30.0, ortho: bool = False, frame_on: str | None = None) -> Camera:
    """The camera that frames the animation (every frame) from the chosen angle: see framing.resolve for what."""
    framed = framing.resolve(anim, frame_on)
    frames = anim.frames if framed.vertices is None else anim.frames[:, framed.vertices]  # a mask: not np.take
    return Camera.fit(frames, size=size, yaw=yaw + framed.yaw, pitch=pitch, fov=fov, ortho=ortho)


def cull(xy: np.ndarray, ndc_z: np.ndarray, w: np.ndarray, faces: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bool (T, F): whole-triangle view-frustum culling plus back-face culling (front = counter-clockwise in GL)."""
    x, y = xy[..., 0], xy[..., 1]
    f0, f1, f2 = faces[:, 0], faces[:, 1], faces[:, 2]
    ax, ay = np.take(x, f0, axis=1), np.take(y, f0, axis=1)
    # Screen y points down, so a counter-clockwise (front) triangle has a negative signed area here.
    x1, y1, x2, y2 = (np.take(a, f, axis=1) for a, f in ((x, f1), (y, f1), (x, f2), (y, f2)))
    area2 = (x1 - ax) * (y2 - ay) - (y1 - ay) * (x2 - ax)
    # Per vertex, one bit per side of the view volume it lies beyond and one for not in front of the eye: a
    # triangle is outside when its three corners share a side, behind when one corner is. (Bits per vertex,
    # then three uint8 gathers: (T, F, 3) gathers and .all(-1) cost 10x more on long clips.)
    bits = np.zeros(x.shape, np.uint8)
    for i, out in enumerate((x < 0, x > width, y < 0, y > height, ndc_z < -1, ndc_z > 1)):
        bits |= out.view(np.uint8) << np.uint8(i)
    bits |= (~(w > 0)).view(np.uint8) << np.uint8(7)
    b0, b1, b2 = (np.take(bits, f, axis=1) for f in (f0, f1, f2))
    outside = (b0 & b1 & b2 & np.uint8(63)) != 0
    behind = ((b0 | b1 | b2) & np.uint8(128)) != 0
    return (area2 < 0) & ~behind & ~outside


def painter_order(depth: np.ndarray, faces: np.ndarray, candidates: np.ndarray, frame: int) -> np.ndarray:
    """Candidate triangle ids sorted back to front by centroid depth at one frame (stable, deterministic)."""
    centroid = depth[frame][faces[candidates]].mean(axis=1)
    return candidates[np.argsort(-centroid, kind="stable")].astype(np.int32)


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
    face_rgb = np.empty((t, f, 3), np.float32)
    vertex_rgb = np.empty((t, v, 3), np.float32) if vertex_colors else None
    tri_rgb, vert_base = anim.triangle_colors()[None], anim.face_base_colors()[None]
    for blk in _blocks(t):
        face_rgb[blk] = lambert(face_normals(frames[blk], faces), tri_rgb, camera.view, lighting)
        if vertex_rgb is not None:
            vertex_rgb[blk] = lambert(vertex_normals(frames[blk], faces), vert_base, camera.view, lighting)
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
