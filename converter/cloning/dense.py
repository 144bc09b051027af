"""Expression cloning by dense correspondence (Noh and Neumann, book chapter 11).

Preprocessing: sparse correspondences (automatic, plus the user's) train an RBF volume morph of the
source onto the target; the morphed source is projected onto the target surface (the deformed source),
and every target vertex is projected back onto the deformed source's triangles (barycentric
coordinates both ways). Each source vertex gets a local frame on the source and on the deformed source;
their rotation and the ratio of the local bounding boxes (limited by the spread of all ratios) turn a
source motion vector into a target one (11.8-11.14). Runtime: one barycentric blend per target vertex.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from converter.animation import FaceAnimation, vertex_normals
from converter.cloning import landmarks, rigid
from converter.cloning.rbf import VolumeMorph
from converter.cloning.surface import adjacency, ball_smooth, interpolate, project_cylindrical, smooth
from converter.errors import InputError
from converter.userfiles import read_bytes

SMOOTHING = 5  # passes of the neighbour-average noise filter on scale factors
NORMAL_RADIUS = 0.03  # normals are averaged over this fraction of the face size


@dataclass(frozen=True)
class DenseMap:
    """Precomputed target-from-source motion transfer."""

    target_ids: np.ndarray  # (n,) deformable target vertices
    corners: np.ndarray  # (n, 3) source vertex of each barycentric corner
    bary: np.ndarray  # (n, 3) barycentric coordinates in the corners' triangle
    transfer: np.ndarray  # (n, 3, 3, 3) bary_k * T_corner_k: target motion = sum_k transfer[:, k] @ m[corner_k]
    rigid_pairs: tuple  # ((source ids, target ids), ...) rigid pieces
    scale: float  # global size ratio target / source
    deformed: np.ndarray  # (Vs, 3) the source embedded in the target surface (for pictures and checks)
    morphed: np.ndarray  # (Vs, 3) the source after the volume morph alone

    def apply(self, source_frames: np.ndarray, target_base: np.ndarray) -> np.ndarray:
        """Target frames (T, Vt, 3) from head-frame source frames (T, Vs, 3)."""
        m = source_frames - source_frames[0]
        out = np.broadcast_to(target_base, (len(source_frames),) + target_base.shape).astype(np.float32).copy()
        mc = m[:, self.corners]  # (T, n, 3, 3)
        out[:, self.target_ids] += np.einsum("nkij,tnkj->tni", self.transfer, mc)
        for src, tgt in self.rigid_pairs:
            out[:, tgt] = rigid.transfer_rigid(source_frames, src, target_base, tgt, self.scale)
        return out


def skin_faces(anim: FaceAnimation) -> np.ndarray:
    """Triangles of the skin part when there is one, else the deformable triangles."""
    skin = [i for i, p in enumerate(anim.parts) if p.name == "skin"]  # a glTF file has a skin part per primitive
    if skin:
        f = anim.faces[np.isin(anim.part_ids, skin)]
        if len(f):
            return f
    return rigid.soft_faces(anim)


def smooth_normals(verts: np.ndarray, faces: np.ndarray, radius: float) -> np.ndarray:
    """Vertex normals averaged over a ball of `radius` (V, 3): the noise filter, made independent of
    tessellation so that a fine source and a coarse target agree where their shapes agree."""
    n = vertex_normals(verts[None].astype(np.float32), faces)[0].astype(np.float64)
    used = np.unique(faces)
    n[used] = ball_smooth(verts[used], n[used], radius)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def local_frames(n: np.ndarray) -> np.ndarray:
    """Per-vertex orthonormal frames (V, 3, 3) from unit normals: rows x (normal), y (up in the tangent plane), z.

    The chapter takes any edge for y; on a fine source embedded in a coarse target an edge's direction is
    mostly projection noise, so the world up direction projected on the tangent plane is used instead
    (the same on both models, so only the normal's turn is measured).
    """
    e = np.where(np.abs(n[:, 1:2]) < 0.9, np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]))
    y = e - (e * n).sum(1, keepdims=True) * n
    y /= np.maximum(np.linalg.norm(y, axis=1, keepdims=True), 1e-12)
    return np.stack([n, y, np.cross(n, y)], axis=1)


def local_scale(src: np.ndarray, dst: np.ndarray, rot: np.ndarray, adj: sparse.csr_matrix) -> np.ndarray:
    """Eq. 11.12: per-axis size of each vertex's neighbourhood box, deformed over rotated source (V, 3)."""
    coo = adj.tocoo()
    i, j = coo.row, coo.col
    order = np.lexsort((j, i))
    i, j = i[order], j[order]
    rs = np.einsum("eab,eb->ea", rot[i], src[j] - src[i])
    rd = dst[j] - dst[i]
    starts = np.flatnonzero(np.r_[True, i[1:] != i[:-1]])
    rows = i[starts]
    size_s = np.zeros((len(src), 3))
    size_d = np.zeros((len(src), 3))
    # The vertex itself is the box's origin, so include 0 in both min and max.
    size_s[rows] = np.maximum.reduceat(np.maximum(rs, 0), starts) - np.minimum.reduceat(np.minimum(rs, 0), starts)
    size_d[rows] = np.maximum.reduceat(np.maximum(rd, 0), starts) - np.minimum.reduceat(np.minimum(rd, 0), starts)
    ref = np.median(size_s[size_s > 0]) if (size_s > 0).any() else 1.0
    ok = (size_s > 0.2 * ref) & (size_d > 0)
    return np.where(ok, size_d / np.where(ok, size_s, 1.0), np.nan)


def limit_scale(scale: np.ndarray, adj: sparse.csr_matrix, fallback: float) -> np.ndarray:
    """Replace factors beyond one standard deviation of all of them by their neighbours' mean, then smooth."""
    out = scale.copy()
    for c in range(3):
        s = out[:, c]
        good = np.isfinite(s)
        if not good.any():
            out[:, c] = fallback
            continue
        med, sd = np.median(s[good]), s[good].std()
        good &= np.abs(s - med) <= sd
        vals = np.where(good, s, 0.0)
        num = adj @ vals
        den = adj @ good.astype(np.float64)
        filled = np.where(den > 0, num / np.maximum(den, 1), med)
        out[:, c] = np.where(good, s, filled)
    return smooth(out, adj, SMOOTHING)


def read_correspondences(path: str | None, source: np.ndarray, target: np.ndarray):
    """User correspondences from a JSON file: {"pairs": [[source vertex id or [x,y,z], target ...], ...]}."""
    if not path:
        return np.zeros((0, 3)), np.zeros((0, 3))
    raw = read_bytes(path, "correspondence file")
    try:
        data = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f'correspondence file {path} is not JSON ({exc}); write {{"pairs": [[s, t], ...]}}.') from None
    pairs = data.get("pairs") if isinstance(data, dict) else None
    if not isinstance(pairs, list) or not pairs:
        raise InputError(f"correspondence file {path} has no \"pairs\" list; write {{\"pairs\": [[s, t], ...]}}.")

    def point(item, verts: np.ndarray, side: str) -> np.ndarray:
        if isinstance(item, int) and not isinstance(item, bool):
            if not 0 <= item < len(verts):
                raise InputError(f"{side} vertex id {item} in {path} is outside 0..{len(verts) - 1}.")
            return verts[item].astype(np.float64)
        if isinstance(item, list) and len(item) == 3 and all(isinstance(c, (int, float)) for c in item):
            return np.array(item, np.float64)
        raise InputError(f"correspondence {item!r} in {path} is neither a vertex id nor [x, y, z].")

    src, tgt = [], []
    for pair in pairs:
        if not isinstance(pair, list) or len(pair) != 2:
            raise InputError(f"each correspondence in {path} must be [source, target], got {pair!r}.")
        src.append(point(pair[0], source, "source"))
        tgt.append(point(pair[1], target, "target"))
    return np.array(src), np.array(tgt)


def merge(auto_s: np.ndarray, auto_t: np.ndarray, user_s: np.ndarray, user_t: np.ndarray, scale: float):
    """Automatic and user correspondences; a user point replaces automatic ones near it on the source."""
    if not len(user_s):
        return auto_s, auto_t
    d = np.linalg.norm(auto_s[:, None] - user_s[None], axis=-1).min(axis=1)
    keep = d > 0.02 * scale
    return np.vstack([auto_s[keep], user_s]), np.vstack([auto_t[keep], user_t])


def fit(source: FaceAnimation, target: FaceAnimation, correspondences: str | None = None) -> DenseMap:
    """Preprocess a source neutral (frame 0) against a target neutral (frame 0)."""
    s_base = source.frames[0].astype(np.float64)
    t_base = target.frames[0].astype(np.float64)
    s_faces, t_faces = rigid.soft_faces(source), rigid.soft_faces(target)
    if not len(s_faces) or not len(t_faces):
        raise InputError("dense cloning needs a deformable surface (not only eyes or teeth) on both faces.")
    size = np.ptp(s_base[np.unique(s_faces)], axis=0).max()
    user_s, user_t = read_correspondences(correspondences, s_base, t_base)
    # With the user's pairs, a face the rules fail on gives the landmarks found before the failure: the pairs
    # stand in for the rest (the error without them says which landmark to give).
    auto_s, auto_t, _ = landmarks.matched(s_base, skin_faces(source), t_base, skin_faces(target), source.name,
                                         target.name, partial=len(user_s) > 0)
    src_pts, tgt_pts = merge(auto_s, auto_t, user_s, user_t, size)
    morph = VolumeMorph.fit(src_pts, tgt_pts)
    scale = np.sqrt(((tgt_pts - tgt_pts.mean(0)) ** 2).sum() / ((src_pts - src_pts.mean(0)) ** 2).sum())
    morphed = morph(s_base)
    t_soft = np.unique(t_faces)
    axis = t_base[t_soft][:, [0, 2]].mean(axis=0)
    s_soft = np.unique(s_faces)
    # Source -> target: embed the morphed source in the target surface.
    s_normals = vertex_normals(morphed[None].astype(np.float32), s_faces)[0].astype(np.float64)
    tri, bary = project_cylindrical(morphed[s_soft], t_base, t_faces, axis, s_normals[s_soft])
    deformed = morphed.copy()
    deformed[s_soft] = interpolate(t_base, t_faces, tri, bary)
    # Target -> deformed source: which source triangle carries each target vertex.
    t_normals = vertex_normals(t_base[None].astype(np.float32), t_faces)[0].astype(np.float64)
    tri_t, bary_t = project_cylindrical(t_base[t_soft], deformed, s_faces, axis, t_normals[t_soft])
    corners = s_faces[tri_t]
    # Motion-vector direction (11.8-11.10) and magnitude (11.12) per source vertex.
    adj = adjacency(s_faces, len(s_base))
    radius = NORMAL_RADIUS * size
    fo = local_frames(smooth_normals(s_base, s_faces, radius))
    # The deformed source lies on the target: its normal is the target's smoothed normal there.
    t_smooth = smooth_normals(t_base, t_faces, radius * scale)
    nd = fo[:, 0].copy()
    nd[s_soft] = interpolate(t_smooth, t_faces, tri, bary)
    fd = local_frames(nd / np.maximum(np.linalg.norm(nd, axis=1, keepdims=True), 1e-12))
    rot = np.einsum("vki,vkj->vij", fd, fo)  # world <- deformed local <- source local <- world
    # Like the scale factors, turns beyond one standard deviation of all turns are noise (folds, the
    # inside of the lips): those vertices keep their direction.
    ang = np.arccos(np.clip((np.einsum("vii->v", rot[s_soft]) - 1) / 2, -1, 1))
    wild = np.zeros(len(rot), bool)
    wild[s_soft] = ang > np.median(ang) + ang.std()
    rot[wild] = np.eye(3)
    s_fac = limit_scale(local_scale(s_base, deformed, rot, adj), adj, scale)
    t_mat = s_fac[:, :, None] * rot  # eq. 11.13: T = S R (S diagonal, world axes)
    transfer = bary_t[:, :, None, None] * t_mat[corners]
    pairs = rigid_pairs(source, target, morph)
    return DenseMap(t_soft, corners, bary_t, transfer.astype(np.float32), pairs, float(scale),
                    deformed.astype(np.float32), morphed.astype(np.float32))


def rigid_pairs(source: FaceAnimation, target: FaceAnimation, morph) -> tuple:
    """Match every rigid piece of the target to the nearest morphed source piece of the same part."""
    sc = rigid.components(source.faces, source.part_ids, source.parts, source.n_vertices)
    tc = rigid.components(target.faces, target.part_ids, target.parts, target.n_vertices)
    if not sc or not tc:
        return ()
    s_cent = morph(np.array([source.frames[0][ids].mean(0) for _, ids in sc]))
    out = []
    for name, ids in tc:
        c = target.frames[0][ids].mean(0)
        options = [k for k, (n, _) in enumerate(sc) if n == name]
        if not options:
            continue
        best = min(options, key=lambda k: float(np.linalg.norm(s_cent[k] - c)))
        out.append((sc[best][1], ids))
    return tuple(out)


def clone(source: FaceAnimation, target: FaceAnimation, head_frames: np.ndarray,
          correspondences: str | None = None) -> np.ndarray:
    """Target frames for head-frame source frames."""
    dmap = fit(source, target, correspondences)
    return dmap.apply(head_frames, target.frames[0])
