"""Rigid motion: head pose factored out before cloning and re-applied after; rigid parts moved as wholes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

if TYPE_CHECKING:
    from converter.animation import FaceAnimation

RIGID_PARTS = ("eye", "iris", "teeth")  # parts that move as solid bodies (eyeballs, teeth)


def kabsch(base: np.ndarray, frames: np.ndarray, weights: np.ndarray | None = None):
    """Per-frame rotation R (T,3,3) and translation t (T,3) with frames ~ base @ R^T + t (weighted)."""
    w = np.ones(base.shape[0]) if weights is None else weights
    w = w / w.sum()
    cb = w @ base
    cf = np.einsum("v,tvc->tc", w, frames)
    h = np.einsum("v,vi,tvj->tij", w, base - cb, frames - cf[:, None, :])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", u, vt)))
    fix = np.ones((len(frames), 3))
    fix[:, 2] = d
    r = np.einsum("tji,tj,tkj->tik", vt, fix, u)
    t = cf - np.einsum("tij,j->ti", r, cb)
    return r, t


@dataclass(frozen=True)
class Pose:
    """Head pose per frame: world = R @ local + t."""

    rotation: np.ndarray  # (T, 3, 3)
    translation: np.ndarray  # (T, 3)

    @property
    def is_identity(self) -> bool:
        """True when no frame moves the head measurably."""
        return bool(np.allclose(self.rotation, np.eye(3), atol=1e-5) and np.allclose(self.translation, 0, atol=1e-5))


def estimate_pose(frames: np.ndarray, vertices: np.ndarray, scale: float) -> Pose:
    """Head pose of every frame relative to frame 0, from the vertices that move least (skull-like points)."""
    f = frames[:, vertices].astype(np.float64)
    base = f[0]
    keep = np.ones(len(vertices), bool)
    for _ in range(3):  # reweight: fit on the steadiest third, which excludes jaw, lips and brows
        r, t = kabsch(base[keep], f[:, keep])
        local = np.einsum("tji,tvj->tvi", r, f - t[:, None, :])  # R^T (x - t)
        resid = np.linalg.norm(local - base, axis=-1).max(axis=0)
        keep = resid <= np.quantile(resid, 0.33)
    pose = Pose(r, t)
    # Sub-micro poses are noise from expression motion; treat them as none so unposed input stays exact.
    if np.abs(r - np.eye(3)).max() < 1e-4 and np.abs(t).max() < 1e-4 * scale:
        return Pose(np.broadcast_to(np.eye(3), r.shape).copy(), np.zeros_like(t))
    return pose


def remove_pose(frames: np.ndarray, pose: Pose) -> np.ndarray:
    """Frames in the head's own frame (pose removed)."""
    if pose.is_identity:
        return frames
    return np.einsum("tji,tvj->tvi", pose.rotation, frames - pose.translation[:, None, :]).astype(np.float32)


def apply_pose(frames: np.ndarray, pose: Pose, source_pivot: np.ndarray, target_pivot: np.ndarray,
               scale: float) -> np.ndarray:
    """Re-apply the source's head pose to target frames: same rotation about the target's pivot, translation scaled."""
    if pose.is_identity:
        return frames
    r, t = pose.rotation, pose.translation
    move = np.einsum("tij,j->ti", r, source_pivot) + t - source_pivot  # where the source pivot went
    out = np.einsum("tij,tvj->tvi", r, frames - target_pivot) + target_pivot + scale * move[:, None, :]
    return out.astype(np.float32)


def components(faces: np.ndarray, part_ids: np.ndarray, parts: tuple, n_vertices: int) -> list[tuple[str, np.ndarray]]:
    """(part name, vertex ids) of every connected piece of a rigid part, in a fixed order."""
    out = []
    for pi, part in enumerate(parts):
        if part.name not in RIGID_PARTS:
            continue
        f = faces[part_ids == pi]
        if not len(f):
            continue
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
        g = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
        _, label = connected_components(g, directed=False)
        used = np.unique(f)
        for lab in np.unique(label[used]):
            out.append((part.name, used[label[used] == lab]))
    out.sort(key=lambda c: (c[0], int(c[1][0])))
    return out


def soft_faces(anim: FaceAnimation) -> np.ndarray:
    """Triangles of the deformable parts (everything but eyeballs and teeth)."""
    rigid_part = np.array([p.name in RIGID_PARTS for p in anim.parts] or [False])
    return anim.faces[~rigid_part[anim.part_ids]]


def transfer_rigid(source_frames: np.ndarray, src_comp: np.ndarray, target_base: np.ndarray, tgt_comp: np.ndarray,
                   scale: float) -> np.ndarray:
    """Frames (T, n, 3) of a target rigid piece that rotates like the source piece and moves `scale` as far."""
    s = source_frames[:, src_comp].astype(np.float64)
    r, t = kabsch(s[0], s)
    cs = s[0].mean(0)
    move = np.einsum("tij,j->ti", r, cs) + t - cs
    b = target_base[tgt_comp].astype(np.float64)
    ct = b.mean(0)
    return np.einsum("tij,vj->tvi", r, b - ct) + ct + scale * move[:, None, :]
