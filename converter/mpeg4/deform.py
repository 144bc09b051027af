"""FAP values -> vertex positions with face definition tables, vectorised over frames."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from converter.errors import InputError
from converter.mpeg4.standard import N_FAPS, fapu_scale
from converter.mpeg4.tables import FaceDefTables

# Rigid groups and their rotations, composed left to right (R = R_yaw R_pitch [R_roll]): eyes, then the head.
RIGID_GROUP_ORDER = {"left_eye": (23, 25), "right_eye": (24, 26), "head": (49, 48, 50)}


def translation_matrix(tables: FaceDefTables) -> sp.csr_matrix:
    """Sparse (3V, 68) matrix: displacement of every vertex coordinate per unit of each FAP (model units)."""
    cached = getattr(tables, "_translation_matrix", None)
    if cached is not None:
        return cached
    rows, cols, vals = [], [], []
    for f, e in tables.entries.items():
        if e.kind != "translate":
            continue
        ids = np.arange(tables.n_vertices) if e.ids is None else e.ids
        w = np.ones(len(ids)) if e.weights is None else e.weights.astype(np.float64)
        for c in range(3):
            if e.direction[c] != 0:
                rows.append(ids * 3 + c)
                cols.append(np.full(len(ids), f - 1))
                vals.append(w * e.direction[c])
    n = tables.n_vertices * 3
    if rows:
        m = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, N_FAPS),
                          dtype=np.float32)
    else:
        m = sp.csr_matrix((n, N_FAPS), dtype=np.float32)
    tables._translation_matrix = m
    return m


def rotation_matrices(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by angles (T,) about one unit axis (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]], np.float64)
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3)[None] + s * k[None] + (1 - c) * (k @ k)[None]


def deform(vertices: np.ndarray, tables: FaceDefTables, values: np.ndarray, fapu: dict[str, float] | None = None
           ) -> np.ndarray:
    """Vertex positions (T, V, 3) float32 for FAP values (T, 68) in FAPU units on the neutral vertices (V, 3)."""
    v0 = np.asarray(vertices, np.float32)
    values = np.asarray(values, np.float64)
    if values.ndim == 1:
        values = values[None]
    if values.ndim != 2 or values.shape[1] != N_FAPS:
        raise InputError(f"FAP values must be (frames, 68), got shape {values.shape}.")
    if v0.shape != (tables.n_vertices, 3):
        raise InputError(
            f"the tables were built for {tables.n_vertices} vertices, the mesh has {len(v0)}; rebuild them."
        )
    a = values * fapu_scale(fapu or tables.fapu)[None]  # model lengths or radians
    a[:, :2] = 0.0
    t = len(a)
    m = translation_matrix(tables)
    disp = m @ np.ascontiguousarray(a.T, dtype=np.float32)  # (3V, T)
    out = np.empty((t, len(v0), 3), np.float32)
    flat = out.reshape(t, -1)
    np.add(disp.T, v0.reshape(1, -1), out=flat)

    jaw = tables.entries.get(3)
    if jaw is not None and np.any(a[:, 2]):
        angle = a[:, 2] / jaw.radius
        rigid = jaw.weights >= 1.0  # teeth, tongue and the chin turn as one; the rest by its weight
        ids = jaw.ids[rigid]
        out[:, ids] = _rotate(out[:, ids], rotation_matrices(jaw.direction, angle), jaw.pivot.astype(np.float32))
        ids = jaw.ids[~rigid]
        out[:, ids] = _weighted_rotation(out[:, ids], jaw.weights[~rigid], jaw, angle.astype(np.float32))

    for order in RIGID_GROUP_ORDER.values():
        present = [f for f in order if f in tables.entries and np.any(a[:, f - 1])]
        if not present:
            continue
        r = np.broadcast_to(np.eye(3), (t, 3, 3))
        for f in present:
            e = tables.entries[f]
            r = r @ rotation_matrices(e.direction, a[:, f - 1])
        e = tables.entries[present[0]]
        pivot = e.pivot.astype(np.float32)
        if e.ids is None:
            out = _rotate(out, r, pivot)
        else:
            out[:, e.ids] = _rotate(out[:, e.ids], r, pivot)
    return out


def _rotate(p: np.ndarray, r: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """pivot + R_t (p - pivot) for points (T, n, 3) and rotations (T, 3, 3), as p R_t^T + (pivot - pivot R_t^T)."""
    rt = r.astype(np.float32).transpose(0, 2, 1)
    out = np.matmul(p, rt)
    out += (pivot - pivot @ rt)[:, None, :]
    return out


def _weighted_rotation(p: np.ndarray, weights: np.ndarray, e, angle: np.ndarray) -> np.ndarray:
    """Rotate points (T, n, 3) about e's axis through its pivot by angle_t * weight_i (Rodrigues, float32)."""
    k = e.direction.astype(np.float32)
    q = p - e.pivot.astype(np.float32)
    theta = angle[:, None] * weights[None, :].astype(np.float32)
    s, c = np.sin(theta), np.cos(theta)
    kq = q[..., 0] * k[0] + q[..., 1] * k[1] + q[..., 2] * k[2]  # axis component
    cross = (k[1] * q[..., 2] - k[2] * q[..., 1],
             k[2] * q[..., 0] - k[0] * q[..., 2],
             k[0] * q[..., 1] - k[1] * q[..., 0])
    out = np.empty_like(q)
    one_c = kq * (1 - c)
    for i in range(3):
        out[..., i] = q[..., i] * c + cross[i] * s + k[i] * one_c + e.pivot[i]
    return out
