"""PLY meshes (Stanford polygon files, ASCII or binary) read with trimesh, vertex order kept (process=False).

Research face data (VOCASET, FaceFormer, BIWI) publishes a PLY/OBJ template and per-sequence vertex arrays; the
template is read here, the arrays in converter.formats.pointcache (as a point cache: `facesvg convert face.ply
--cache anim.npy`, or a zip holding both).
"""

from __future__ import annotations

import io

import numpy as np

from converter.animation import DEFAULT_PART_COLORS, FaceAnimation, Part
from converter.errors import InputError

DEFAULT_FPS = 30.0


def read_ply(data: bytes, name: str = "mesh.ply") -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(vertices (V,3) float32, triangles (F,3) int32, vertex colours (V,3) 0..1 or None) of a PLY mesh."""
    import trimesh  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    if data[:3] != b"ply":
        raise InputError(f"{name} is not a PLY file (it does not start with 'ply').")
    try:
        mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    except Exception as exc:  # trimesh raises many types on malformed headers and truncated bodies
        raise InputError(f"{name} is not a readable PLY file ({type(exc).__name__}: {str(exc)[:60]}); "
                         "re-export it.") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{name} holds points but no faces; export the mesh with its faces.")
    v = np.asarray(mesh.vertices, np.float32)
    f = np.asarray(mesh.faces, np.int64)
    if not np.isfinite(v).all():
        raise InputError(f"{name} has NaN or infinite vertex positions; re-export it.")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{name}: a face refers to a vertex that does not exist; the file is corrupt.")
    colors = None
    if mesh.visual.kind == "vertex":
        rgb = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(np.float32) / 255.0
        if b"property uchar red" in data[:4096] or b"property float red" in data[:4096]:
            colors = rgb  # only colours the file has: trimesh fills in a default grey otherwise
    return v, f.astype(np.int32), colors


def load_ply_static(data: bytes, fps: float | None = None, name: str = "face") -> FaceAnimation:
    """A PLY mesh on its own: a one-frame animation (a template, a face to clone onto, a still)."""
    v, f, colors = read_ply(data, f"{name}.ply")
    return FaceAnimation(v[None], f, np.zeros(len(f), np.int32), (Part("skin", DEFAULT_PART_COLORS["skin"]),),
                         float(fps) if fps else DEFAULT_FPS, name, vertex_colors=colors, extras={"static": True})
