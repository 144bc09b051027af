"""glTF skins, as the glTF 2.0 spec defines them: linear blend skinning of morphed positions by joint matrices.

A vertex's world position is sum_k w_k * globalTransform(joint_k) * inverseBindMatrix_k * v, with v after morph
targets. The skinned mesh node's own transform is not used; the joints' ancestors (the skeleton root's parents
too) are, through their global transforms.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from converter.errors import InputError

CHUNK_NUMBERS = 1 << 22  # numbers of blended 3x4 matrices held at once (32 MB of float64): frames go in chunks


def joint_matrices(joint_world: list[np.ndarray], inverse_bind: np.ndarray, n_frames: int) -> np.ndarray:
    """(T, J, 3, 4) top rows of globalTransform(joint) @ inverseBindMatrix for every frame."""
    world = np.stack([np.broadcast_to(w, (n_frames, 4, 4)) for w in joint_world], axis=1)
    return (world @ inverse_bind[None])[:, :, :3, :]


def influences(joints: list[np.ndarray], weights: list[np.ndarray], n_vertices: int, name: str,
               mesh_index: int) -> tuple[np.ndarray, np.ndarray]:
    """(joint indices (V, K) int64, weights (V, K) summing to 1) from every JOINTS_n/WEIGHTS_n set of a primitive."""
    for n, (j, w) in enumerate(zip(joints, weights)):
        if j.shape != (n_vertices, 4) or w.shape != (n_vertices, 4):
            raise InputError(f"{name}: JOINTS_{n}/WEIGHTS_{n} of mesh {mesh_index} do not hold 4 values for each of "
                             f"its {n_vertices} vertices; re-export the skin.")
    j = np.concatenate(joints, axis=1).astype(np.int64)
    w = np.concatenate(weights, axis=1).astype(np.float64)
    if not np.isfinite(w).all() or (w < 0).any():
        raise InputError(f"{name}: mesh {mesh_index} has negative or non-finite skin weights; re-export the skin.")
    total = w.sum(axis=1, keepdims=True)
    # A vertex no joint moves (all weights zero) stays where the mesh puts it instead of collapsing to the origin.
    return j, np.where(total > 0, w / np.where(total > 0, total, 1.0), 0.0)


def check_joint_indices(joints: np.ndarray, weights: np.ndarray, n_joints: int, name: str, node: str) -> None:
    """InputError when a weighted influence names a joint the skin does not have."""
    bad = (weights > 0) & ((joints < 0) | (joints >= n_joints))
    if bad.any():
        v = int(np.argwhere(bad)[0, 0])
        raise InputError(f"{name}: vertex {v} of node {node} is weighted to joint {int(joints[bad][0])}, but its skin "
                         f"has {n_joints} joints; re-export the skin.")


def skin_positions(local: np.ndarray, joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """(T, V, 3) skinned positions of local (T or 1, V, 3) by influences (V, K) and joint matrices (T, J, 3, 4)."""
    n_frames, n_joints = matrices.shape[:2]
    n_vertices = local.shape[1]
    joints = np.clip(joints, 0, n_joints - 1)  # out-of-range indices carry zero weight (checked before)
    # Vertex-by-joint weights as a sparse matrix: blending every vertex's matrix is one sparse product per chunk.
    rows = np.repeat(np.arange(n_vertices), joints.shape[1])
    blend = sparse.csr_matrix((weights.reshape(-1), (rows, joints.reshape(-1))), shape=(n_vertices, n_joints))
    unweighted = weights.sum(axis=1) == 0
    out = np.empty((n_frames, n_vertices, 3), np.float32)
    step = max(1, CHUNK_NUMBERS // max(1, 12 * n_vertices))
    for a in range(0, n_frames, step):
        m = matrices[a:a + step]
        blended = (blend @ m.transpose(1, 0, 2, 3).reshape(n_joints, -1)).reshape(n_vertices, len(m), 3, 4)
        h = local if len(local) == 1 else local[a:a + step]
        out[a:a + len(m)] = (np.einsum("vtij,tvj->tvi", blended[..., :3], np.broadcast_to(h, (len(m),) + h.shape[1:]))
                             + blended[..., 3].transpose(1, 0, 2))
    if unweighted.any():  # a vertex no joint moves stays where the mesh puts it instead of collapsing to the origin
        out[:, unweighted] = np.broadcast_to(local[:, unweighted], (n_frames, int(unweighted.sum()), 3))
    return out
