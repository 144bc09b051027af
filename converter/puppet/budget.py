"""The puppet's triangle budget: only the triangles some pose shows, on a mesh simplified within a pixel bound.

The player draws every triangle of the puppet every frame, so its triangles are its frame cost (software GL drew a
dense head's triangles too slowly for the display rate: bench_puppet). Two steps cut them, both by default
(model.build):

1. Occlusion (`seen`). The puppet's poses are sampled: rest, each target at its keyforms, the head over the
   visibility grid, each eye over a coarser one, the target that moves most under head turns, and SEEDED_POSES
   random combinations of targets, head and eye angles. A triangle that no sampled pose shows by the occlusion
   pass's rule (converter.idpass: it owns a pixel centre, or it is a sub-pixel triangle not behind the surface) is
   dropped: the inside of the mouth behind closed lips, the eyeball behind the lids, the teeth's far sides.
2. Simplification (`simplified`), where more than MAX_TRIANGLES are shown. Each part's shown triangles are simplified
   towards its share of MAX_TRIANGLES by meshoptimizer's edge collapse onto
   a subset of its vertices (converter.simplify's binding: the morph tables carry over by indexing), within
   BOUND_PX of the surface at the output size, its quadric error extended with the targets' motion
   (simplify.motion_attributes over the rest and each target at weight 1) so that lips, lids and brows keep the
   vertices they move with; vertices shared by two parts stay, so the parts meet without cracks.
"""

from __future__ import annotations

import numpy as np

from converter import idpass, simplify
from converter.blendshapes import eye_vertices, rotations
from converter.camera import Camera
from converter.extract import cull
from converter.formats.morphs import MorphFace
from converter.mpeg4.tables import sphere_center

BOUND_PX = 0.5  # px at the output size: meshoptimizer's error bound on the simplified surface
MAX_TRIANGLES = 16000  # a mesh that shows more is simplified towards this many (never past BOUND_PX); one that shows
# fewer is kept whole: the Ready Player Me avatar's draw at the display rate (bench_puppet), and simplifying them
# cost SSIM against our prerender
MORPH_WEIGHTS = (0.5, 1.0)  # each target's sampled weights
HEAD_GRID = tuple(float(a) for a in range(-40, 41, 10))  # degrees of head yaw and pitch sampled (model's grid)
EYE_GRID = (-40.0, 0.0, 40.0)  # ... and of each eye's
WIDEST_GRID = (-40.0, 0.0, 40.0)  # ... of the head with the widest-moving target at 1
SEEDED_POSES = 32  # random combinations of targets and angles sampled (a fixed seed: the same puppet every build)
COMBO_SHARE = 0.25  # the share of targets set in each random combination
HEAD_RANGE, ROLL_RANGE, EYE_RANGE = 40.0, 20.0, 30.0  # degrees: the random combinations' angles lie within these
POSE_BLOCK = 200  # poses the occlusion pass reads at a time (a dense head's poses are 0.3 MB each)
EDGE_SCALE_QUANTILE = 0.9  # of the kept edges' px / world length ratios: px per world unit facing the camera


def turned(points: np.ndarray, centre: np.ndarray, ypr_degrees: np.ndarray) -> np.ndarray:
    """(P, N, 3) float32 points turned about centre by each (yaw, pitch, roll) row (degrees) of ypr_degrees (P, 3),
    as blendshapes.drive turns them."""
    r = rotations(np.radians(np.asarray(ypr_degrees, np.float64)).astype(np.float32)).astype(np.float32)
    c = np.asarray(centre, np.float32)
    return (np.asarray(points, np.float32) - c) @ np.swapaxes(r, 1, 2) + c


def _grid(angles: tuple[float, ...]) -> np.ndarray:
    """(A * A, 3) yaw, pitch, 0 over the grid (degrees)."""
    return np.array([[y, p, 0.0] for y in angles for p in angles], np.float64)


def poses(face: MorphFace, pivot: np.ndarray, seed: int = 0):
    """The sampled poses (see the module docstring) as blocks of (n, V, 3) float32 points, in turn."""
    base = face.base.astype(np.float32)
    deltas = face.deltas
    yield base[None]
    for k in range(len(face.names)):
        yield base[None] + np.array(MORPH_WEIGHTS, np.float32)[:, None, None] * deltas[k][None]
    yield turned(base, pivot, _grid(HEAD_GRID))
    for ids in eye_vertices(face) or ():
        block = np.repeat(base[None], len(EYE_GRID) ** 2, axis=0)
        block[:, ids] = turned(base[ids], sphere_center(face.base[ids]), _grid(EYE_GRID))
        yield block
    if len(face.names):
        widest = int(np.argmax(np.linalg.norm(deltas, axis=2).sum(axis=1)))
        yield turned(base + deltas[widest], pivot, _grid(WIDEST_GRID))
    rng = np.random.default_rng(seed)
    sides = eye_vertices(face) or ()
    for _ in range(SEEDED_POSES):
        w = rng.uniform(0, 1, len(face.names)) * (rng.uniform(0, 1, len(face.names)) < COMBO_SHARE)
        pts = base + np.tensordot(w.astype(np.float32), deltas, axes=1)
        for ids in sides:
            eye = rng.uniform(-EYE_RANGE, EYE_RANGE, 2)
            pts[ids] = turned(pts[ids], sphere_center(face.base[ids]), np.array([[eye[0], eye[1], 0.0]]))[0]
        head = [rng.uniform(-HEAD_RANGE, HEAD_RANGE), rng.uniform(-HEAD_RANGE, HEAD_RANGE),
                rng.uniform(-ROLL_RANGE, ROLL_RANGE)]
        yield turned(pts, pivot, np.array([head]))


def seen(face: MorphFace, camera: Camera, pivot: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Bool (F,): the candidate triangles some sampled pose shows (idpass.ever_seen over the poses, only the
    candidates drawn)."""
    faces = np.ascontiguousarray(face.faces, np.int64)
    out = np.zeros(len(faces), bool)
    pending: list[np.ndarray] = []

    def flush() -> None:
        frames = np.ascontiguousarray(np.concatenate(pending), np.float32)
        pending.clear()
        xy, z, w = camera.project(frames)
        visible = cull(xy, z, w, faces, camera.width, camera.height) & candidates
        out[:] |= idpass.ever_seen(frames, faces, camera, visible)

    for block in poses(face, pivot):
        pending.append(block)
        if sum(len(b) for b in pending) >= POSE_BLOCK:
            flush()
    if pending:
        flush()
    return out


def px_per_unit(camera: Camera, points: np.ndarray, faces: np.ndarray) -> float:
    """Output px per world unit on the face, for edges facing the camera (a high quantile of the edges' ratios)."""
    xy = camera.project(np.asarray(points, np.float32)[None])[0][0]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    world = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    px = np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1)
    ok = (world > 0) & np.isfinite(px)
    return float(np.quantile(px[ok] / world[ok], EDGE_SCALE_QUANTILE)) if ok.any() else 0.0


def simplified(face: MorphFace, camera: Camera, keep: np.ndarray, bound_px: float | None = None,
               max_triangles: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(faces (F', 3) int32 over the face's vertices, part id of each) of the kept triangles (bool (F,)): as they are
    when at most max_triangles (MAX_TRIANGLES by default), else each part simplified towards its share of them,
    never past bound_px (BOUND_PX by default) at the camera's size (see the module docstring)."""
    faces, part_ids = face.faces[keep].astype(np.int64), face.part_ids[keep]
    max_triangles = MAX_TRIANGLES if max_triangles is None else max_triangles
    bound_px = BOUND_PX if bound_px is None else bound_px
    if len(faces) <= max_triangles or bound_px <= 0:
        return faces.astype(np.int32), part_ids
    positions = np.ascontiguousarray(face.base, np.float32)
    scale = px_per_unit(camera, face.base.astype(np.float64), faces)
    extent = float(np.ptp(positions, axis=0).max())  # meshoptimizer's error is relative to the buffer's extent
    if scale <= 0 or extent <= 0:
        return faces.astype(np.int32), part_ids
    error = bound_px / scale / extent
    frames = np.concatenate([positions[None], positions[None] + face.deltas]).astype(np.float32)
    attrs = np.ascontiguousarray(simplify.motion_attributes(frames), np.float32)
    parts = np.unique(part_ids)
    owners = np.zeros(len(positions), np.int64)
    for p in parts:  # vertices two parts share stay, so the parts still meet
        owners[np.unique(faces[part_ids == p])] += 1
    lock = np.ascontiguousarray(owners > 1, np.uint8)
    fn = simplify._simplify_with_attributes()
    share = max_triangles / len(faces)
    pieces = [simplify._part_simplify(fn, positions, attrs, lock, faces[part_ids == p],
                                      int(share * np.count_nonzero(part_ids == p)), 0, error) for p in parts]
    out_parts = np.concatenate([np.full(len(x), p, np.int32) for x, p in zip(pieces, parts)])
    return np.concatenate(pieces).astype(np.int32), out_parts
