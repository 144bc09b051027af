"""Section 12.3.2's influence computation: distance along mesh edges, influence lists, weights (eq. 12.1-12.2)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges (E, 2) of a triangle mesh."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    return np.unique(np.sort(e, axis=1), axis=0)


def mouth_cut(vertices: np.ndarray, edges: np.ndarray, corners: tuple[np.ndarray, np.ndarray], mid: np.ndarray,
              axes: np.ndarray, reach: float) -> np.ndarray:
    """Edges that cross the lip line between the mouth corners (a mesh with a closed mouth): True = cut.

    The lip line runs through the right corner, the lip contact midpoint and the left corner; an edge is cut when
    its ends lie on opposite sides of it, within reach of it and in front of the mouth's depth minus reach.
    """
    local = (vertices - mid) @ axes.T
    cr, cl = (corners[1] - mid) @ axes.T, (corners[0] - mid) @ axes.T
    x = local[:, 0]
    line = np.where(x >= 0, cl[1] * np.clip(x / max(cl[0], 1e-9), 0, 1), cr[1] * np.clip(x / min(cr[0], -1e-9), 0, 1))
    dy = local[:, 1] - line
    inside = (x > cr[0] * 0.97) & (x < cl[0] * 0.97) & (np.abs(dy) < reach) & (local[:, 2] > -reach)
    a, b = edges[:, 0], edges[:, 1]
    return inside[a] & inside[b] & (dy[a] * dy[b] < 0)


def edge_graph(vertices: np.ndarray, faces: np.ndarray, keep: np.ndarray | None = None,
               cut: np.ndarray | None = None) -> sp.csr_matrix:
    """Symmetric sparse graph of mesh edges weighted by Euclidean length; edges touching a dropped vertex, or
    marked in cut (aligned with mesh_edges), removed."""
    e = mesh_edges(faces)
    if cut is not None:
        e = e[~cut]
    if keep is not None:
        e = e[keep[e[:, 0]] & keep[e[:, 1]]]
    w = np.linalg.norm(vertices[e[:, 0]].astype(np.float64) - vertices[e[:, 1]], axis=1)
    w = np.maximum(w, 1e-12)  # csgraph treats explicit zeros as missing edges
    n = len(vertices)
    g = sp.coo_matrix(
        (np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n)
    )
    return g.tocsr()


def geodesic(graph: sp.csr_matrix, sources: np.ndarray, limit: float = np.inf) -> np.ndarray:
    """(K, V) shortest-path distances along edges from each source vertex (inf beyond limit or unreachable)."""
    if len(sources) == 0:
        return np.zeros((0, graph.shape[0]))
    return dijkstra(graph, directed=False, indices=np.asarray(sources), limit=limit)


def attach_unreachable(graph: sp.csr_matrix, vertices: np.ndarray, anchors: np.ndarray,
                       movable: np.ndarray) -> np.ndarray:
    """For each vertex, the vertex whose weights it copies: itself, or for a movable vertex in a component without
    any anchor (eyelashes, loose shells), the nearest vertex (Euclidean) of a component that has one."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    n_comp, label = connected_components(graph, directed=False)
    has_anchor = np.zeros(n_comp, bool)
    has_anchor[label[anchors]] = True
    src = np.arange(len(vertices))
    loose = movable & ~has_anchor[label]
    target = np.flatnonzero(movable & has_anchor[label])
    if loose.any() and target.size:
        _, nearest = cKDTree(vertices[target]).query(vertices[loose])
        src[loose] = target[nearest]
    return src


def raised_cosine(t: np.ndarray) -> np.ndarray:
    """1 at 0 falling smoothly to 0 at 1 and beyond."""
    t = np.clip(t, 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * t))


def influence_weights(points: np.ndarray, fp_pos: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Normalised influence weights (n, K) of K feature points on n vertices (section 12.3.2).

    points (n, 3) vertex positions, fp_pos (K, 3) feature-point positions, dist (K, n) distances along edges.
    Influence list: take the closest remaining feature point, drop every feature point beyond the plane through it
    perpendicular to vertex->feature point, repeat. Weights: d = sum(d_i cos t_i) / sum(cos t_i) (eq. 12.1),
    W_i = sin(pi/2 (1 - d_i / d)) (eq. 12.2), clipped at 0, then normalised to sum 1 per vertex.
    """
    n, k = points.shape[0], fp_pos.shape[0]
    d = dist.T  # (n, K)
    finite = np.isfinite(d)
    order = np.argsort(np.where(finite, d, np.inf), axis=1, kind="stable")
    rows = np.arange(n)
    active = finite.copy()
    selected = np.zeros((n, k), bool)
    for step in range(k):
        j = order[:, step]
        ok = active[rows, j]
        if not ok.any():
            continue
        selected[rows[ok], j[ok]] = True
        normal = fp_pos[j] - points  # (n, 3)
        beyond = np.einsum("nkc,nc->nk", fp_pos[None, :, :] - fp_pos[j][:, None, :], normal) > 0
        active &= ~(beyond & ok[:, None])
        active[rows, j] = False
    closest = order[:, 0]
    v1 = fp_pos[closest] - points
    vi = fp_pos[None, :, :] - points[:, None, :]
    n1 = np.linalg.norm(v1, axis=1)
    ni = np.linalg.norm(vi, axis=2)
    cos = np.einsum("nkc,nc->nk", vi, v1) / np.maximum(ni * n1[:, None], 1e-12)
    cos[rows, closest] = 1.0
    cos = np.where(selected, cos, 0.0)
    dd = np.where(selected, d, 0.0)
    den = cos.sum(1)
    mean_d = np.where(den > 1e-9, (dd * cos).sum(1) / np.where(den > 1e-9, den, 1), np.where(selected, d, 0).sum(1)
                      / np.maximum(selected.sum(1), 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.sin(0.5 * np.pi * (1.0 - dd / mean_d[:, None]))
    w = np.where(selected & np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
    s = w.sum(1)
    w = np.where(s[:, None] > 0, w / np.where(s > 0, s, 1)[:, None], 0.0)
    # A vertex on a feature point (or with all weights clipped) belongs to its closest feature point alone.
    lone = (s <= 0) | (n1 < 1e-9)
    w[lone] = 0.0
    w[rows[lone], closest[lone]] = 1.0
    w[~finite.any(1)] = 0.0
    return w


def smoothing_operator(graph: sp.csr_matrix) -> sp.csr_matrix:
    """Row-stochastic neighbour-average operator of the edge graph (isolated vertices keep their value)."""
    a = (graph != 0).astype(np.float64)
    deg = np.asarray(a.sum(1)).ravel()
    inv = sp.diags(np.where(deg > 0, 1.0 / np.maximum(deg, 1), 0.0))
    return (inv @ a + sp.diags((deg == 0).astype(np.float64))).tocsr()


def smooth(op: sp.csr_matrix, field: np.ndarray, iterations: int) -> np.ndarray:
    """Diffuse a per-vertex field (V, K) along mesh edges: the "normalisation that keeps skin coherent"."""
    out = np.asarray(field, np.float64)
    for _ in range(iterations):
        out = 0.5 * out + 0.5 * (op @ out)
    return out


def smoothing_iterations(graph: sp.csr_matrix, radius: float) -> int:
    """Iterations of smooth() that spread over about radius (diffusion grows with the square root of steps)."""
    lengths = graph.data
    edge = float(np.median(lengths)) if lengths.size else 1.0
    return int(np.clip(round(2.0 * (radius / max(edge, 1e-12)) ** 2), 1, 200))
