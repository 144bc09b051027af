"""Surface queries the cloning methods share: adjacency, boundary loops, ray casting, projection to triangles."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

BARY_TOL = 0.005  # the chapter's slack on barycentric tests (11.3)
GRAZING_COS = 1.01  # below this |cos| between ray and normal the nearest point replaces the ray hit


def adjacency(faces: np.ndarray, n_vertices: int) -> sparse.csr_matrix:
    """Symmetric vertex adjacency (V, V) with ones on mesh edges."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    a = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices)).tocsr()
    a = ((a + a.T) > 0).astype(np.float64)
    return a.tocsr()


def smooth(values: np.ndarray, adj: sparse.csr_matrix, iterations: int = 1) -> np.ndarray:
    """Average each value with its neighbours' (the chapter's noise filter), `iterations` times."""
    a = adj + sparse.identity(adj.shape[0], format="csr")
    deg = np.asarray(a.sum(axis=1)).ravel()
    out = values.astype(np.float64)
    for _ in range(iterations):
        out = (a @ out.reshape(len(out), -1)).reshape(out.shape) / deg.reshape((-1,) + (1,) * (out.ndim - 1))
    return out


def ball_smooth(points: np.ndarray, values: np.ndarray, radius: float) -> np.ndarray:
    """Mean of values over all points within radius of each point: a tessellation-independent filter."""
    tree = cKDTree(points)
    m = tree.sparse_distance_matrix(tree, radius, output_type="coo_matrix")
    m = sparse.csr_matrix((np.ones(len(m.data)), (m.row, m.col)), shape=(len(points), len(points)))
    m = m + sparse.identity(len(points), format="csr")
    return (m @ values) / np.asarray(m.sum(axis=1))


def triangle_frames(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corner a, edges ab and ac of every triangle."""
    a = verts[faces[:, 0]].astype(np.float64)
    return a, verts[faces[:, 1]] - a, verts[faces[:, 2]] - a


def ray_hits(origins: np.ndarray, dirs: np.ndarray, verts: np.ndarray, faces: np.ndarray, cand: np.ndarray):
    """Moeller-Trumbore for each ray against its candidate triangles (n, k): t (n, k) and bary (n, k, 3).

    t is nan where the ray misses (parallel or outside the triangle by more than BARY_TOL).
    """
    a, e1, e2 = triangle_frames(verts, faces)
    a, e1, e2 = a[cand], e1[cand], e2[cand]
    d = dirs[:, None, :]
    p = np.cross(d, e2)
    det = np.einsum("nkc,nkc->nk", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origins[:, None, :] - a
    u = np.einsum("nkc,nkc->nk", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("nkc,nkc->nk", d, q) * inv
    t = np.einsum("nkc,nkc->nk", e2, q) * inv
    bary = np.stack([1 - u - v, u, v], axis=-1)
    inside = ok & (bary >= -BARY_TOL).all(-1) & (bary <= 1 + BARY_TOL).all(-1)
    return np.where(inside, t, np.nan), bary


def closest_on_candidates(points: np.ndarray, verts: np.ndarray, faces: np.ndarray, cand: np.ndarray,
                          penalty: np.ndarray | None = None):
    """For each point, the nearest of its candidate triangles (n, k): (triangle, bary, distance).

    The point is projected on each triangle's plane and its barycentric coordinates clamped to the
    triangle, which is exact inside and a close approximation near edges.
    """
    a, e1, e2 = triangle_frames(verts, faces)
    a, e1, e2 = a[cand], e1[cand], e2[cand]
    w = points[:, None, :] - a
    d11 = np.einsum("nkc,nkc->nk", e1, e1)
    d12 = np.einsum("nkc,nkc->nk", e1, e2)
    d22 = np.einsum("nkc,nkc->nk", e2, e2)
    w1 = np.einsum("nkc,nkc->nk", w, e1)
    w2 = np.einsum("nkc,nkc->nk", w, e2)
    den = d11 * d22 - d12 * d12
    den = np.where(np.abs(den) > 1e-18, den, 1e-18)
    u = (d22 * w1 - d12 * w2) / den
    v = (d11 * w2 - d12 * w1) / den
    bary = np.clip(np.stack([1 - u - v, u, v], -1), 0.0, None)
    bary /= np.maximum(bary.sum(-1, keepdims=True), 1e-12)
    q = a + bary[..., 1:2] * e1 + bary[..., 2:3] * e2
    dist = np.linalg.norm(q - points[:, None, :], axis=-1)
    j = np.argmin(dist if penalty is None else dist + penalty, axis=1)
    rows = np.arange(len(points))
    return cand[rows, j], bary[rows, j], dist[rows, j]


def candidates(points: np.ndarray, verts: np.ndarray, faces: np.ndarray, k: int = 24,
               allowed: np.ndarray | None = None) -> np.ndarray:
    """Ids (n, k) of the k triangles whose centroids are nearest each point (optionally among `allowed`)."""
    ids = np.arange(len(faces)) if allowed is None else np.flatnonzero(allowed)
    cent = verts[faces[ids]].mean(axis=1)
    k = min(k, len(ids))
    _, j = cKDTree(cent).query(points, k=k)
    return ids[np.asarray(j).reshape(len(points), k)]


def project_cylindrical(points: np.ndarray, verts: np.ndarray, faces: np.ndarray, axis_xz: np.ndarray,
                        normals: np.ndarray | None = None, k: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Each point's triangle and barycentric coordinates on the surface (11.3-11.7).

    The ray is perpendicular to the vertical centreline through axis_xz and passes through the point;
    of the valid hits the one nearest the point wins. With point normals, triangles facing the other way
    are refused: that keeps a lower-lip point off upper-lip triangles where the lips touch (11.5).
    Points whose ray misses every nearby triangle (surface borders, the top of the head) fall back to the
    nearest surface point.
    """
    points = np.asarray(points, np.float64)
    cand = candidates(points, verts, faces, k)
    origin = points.copy()
    origin[:, 0], origin[:, 2] = axis_xz[0], axis_xz[1]
    dirs = points - origin
    t, bary = ray_hits(origin, dirs, verts, faces, cand)
    penalty = None
    if normals is not None:
        _, e1, e2 = triangle_frames(verts, faces)
        fn = np.cross(e1, e2)
        facing = np.einsum("nkc,nc->nk", fn[cand], normals) > 0
        t = np.where(facing, t, np.nan)
        penalty = np.where(facing, 0.0, np.inf)
    gap = np.abs(t - 1.0) * np.linalg.norm(dirs, axis=1)[:, None]
    gap = np.where(np.isnan(gap), np.inf, gap)
    j = np.argmin(gap, axis=1)
    rows = np.arange(len(points))
    tri = cand[rows, j]
    b = np.clip(bary[rows, j], 0.0, None)
    b /= np.maximum(b.sum(-1, keepdims=True), 1e-12)
    ctri, cb, cdist = closest_on_candidates(points, verts, faces, cand, penalty)
    # A hit far beyond the nearest surface point went through a hole or grazed a fold: use the nearest point.
    miss = ~np.isfinite(gap[rows, j]) | (gap[rows, j] > 3.0 * cdist + 1e-9)
    if normals is not None:
        # A ray grazing the surface (under the chin, the top of the head) slides far along it: there
        # the nearest surface point is the better embedding.
        cos = np.abs((dirs * normals).sum(1)) / np.maximum(np.linalg.norm(dirs, axis=1), 1e-12)
        miss |= cos < GRAZING_COS
    tri = np.where(miss, ctri, tri)
    b = np.where(miss[:, None], cb, b)
    return tri.astype(np.int64), b


def interpolate(values: np.ndarray, faces: np.ndarray, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Barycentric interpolation of per-vertex values (..., V, C) at surface points (n,)."""
    idx = faces[tri]  # (n, 3)
    return np.einsum("...nkc,nk->...nc", values[..., idx, :], bary)


def ray_cast(origins: np.ndarray, dirs: np.ndarray, verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """First hit distance t (n,) of each ray with the whole mesh (nan on a miss); brute force in chunks."""
    out = np.full(len(origins), np.nan)
    n_f = len(faces)
    for s in range(0, len(origins), max(1, 2_000_000 // max(n_f, 1))):
        sl = slice(s, s + max(1, 2_000_000 // max(n_f, 1)))
        cand = np.broadcast_to(np.arange(n_f), (len(origins[sl]), n_f))
        t, _ = ray_hits(origins[sl], dirs[sl], verts, faces, cand)
        t = np.where(t > 0, t, np.nan)
        with np.errstate(all="ignore"):
            out[sl] = np.where(np.isnan(t).all(1), np.nan, np.nanmin(np.where(np.isnan(t), np.inf, t), axis=1))
    return out
