"""Example-based expression cloning (Pyun et al., seed 000): key-model pairs blended by cardinal RBF weights.

Preprocessing: emotional and verbal key-models are composited (per-vertex importance, appendix); the
source key-models' feature-point displacement vectors are reduced by PCA to parameter vectors; weight
functions of linear plus cubic B-spline radial bases interpolate the key-models cardinally. Runtime:
parameter vector of the input frame -> weights -> blend of the target key-models (eq. 9-11).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from converter.cloning.rbf import CardinalWeights
from converter.errors import InputError

FEATURES = 24  # feature points picked automatically (the paper uses about 20)
PCA_THRESHOLD = 1e-5  # eigenvalues below this fraction of the largest are dropped


@dataclass(frozen=True)
class KeyPairs:
    """Source and target base models with M corresponding key-models each."""

    source_base: np.ndarray  # (Vs, 3)
    target_base: np.ndarray  # (Vt, 3)
    source: np.ndarray  # (M, Vs, 3)
    target: np.ndarray  # (M, Vt, 3)
    names: tuple[str, ...]
    kinds: tuple[str, ...]  # "emotional", "verbal" or "other" per key
    feature_ids: np.ndarray | None = None  # source vertex ids, or None to pick them automatically


def importance(base: np.ndarray, emotional: np.ndarray, verbal: np.ndarray, l_p: float, l_e: float,
               s1: float = 0.5, s2: float = 0.5) -> np.ndarray:
    """Per-vertex importance alpha in [0, 1] of verbal over emotional motion (appendix, eq. 13)."""

    def first(keys: np.ndarray) -> np.ndarray:
        m = np.linalg.norm(keys - base, axis=-1).max(axis=0)
        return m / m.max() if m.max() > 0 else m

    def spread(v: np.ndarray, radius: float) -> np.ndarray:
        strong = np.flatnonzero(v > s1)
        if not len(strong) or radius <= 0:
            return v
        d = cKDTree(base).sparse_distance_matrix(cKDTree(base[strong]), radius, output_type="coo_matrix")
        out = v.copy()
        np.maximum.at(out, d.row, v[strong][d.col])
        return out

    p2 = spread(first(verbal), l_p)
    e2 = spread(first(emotional), l_e)
    return np.where(p2 < s2, p2 * (1 - e2), 1 - (1 - p2) * e2)


def composite(base: np.ndarray, emotional: np.ndarray, verbal: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Combined key-model of an emotional and a verbal key-model (section 2): the stronger side is kept whole."""
    de, dp = emotional - base, verbal - base

    def perp(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # component of a perpendicular to b
        bb = (b * b).sum(-1, keepdims=True)
        return a - np.where(bb > 0, (a * b).sum(-1, keepdims=True) / np.where(bb > 0, bb, 1), 0) * b

    a = alpha[:, None]
    return base + np.where(a >= 0.5, dp + (1 - a) * perp(de, dp), de + a * perp(dp, de))


def with_composites(pairs: KeyPairs) -> KeyPairs:
    """Add every emotional x verbal combination on both sides (the paper's 6 x 13 from 6 + 13)."""
    emo = [i for i, k in enumerate(pairs.kinds) if k == "emotional"]
    verb = [i for i, k in enumerate(pairs.kinds) if k == "verbal"]
    if not emo or not verb:
        return pairs
    sides = []
    for base, keys in ((pairs.source_base, pairs.source), (pairs.target_base, pairs.target)):
        size = np.ptp(base, axis=0).max()
        alpha = importance(base, keys[emo], keys[verb], 0.05 * size, 0.05 * size)
        sides.append(np.stack([composite(base, keys[e], keys[v], alpha) for e in emo for v in verb]))
    names = tuple(f"{pairs.names[e]}+{pairs.names[v]}" for e in emo for v in verb)
    return KeyPairs(pairs.source_base, pairs.target_base, np.concatenate([pairs.source, sides[0]]),
                    np.concatenate([pairs.target, sides[1]]), pairs.names + names,
                    pairs.kinds + ("composite",) * len(names), pairs.feature_ids)


def pick_features(base: np.ndarray, keys: np.ndarray, count: int = FEATURES) -> np.ndarray:
    """Feature points spread over the moving parts: farthest-point sampling among vertices that move."""
    motion = np.linalg.norm(keys - base, axis=-1).max(axis=0)
    moving = np.flatnonzero(motion > 0.2 * motion.max())
    if len(moving) == 0:
        raise InputError("the source key-models do not differ from their base; give key-models with expressions.")
    chosen = [moving[np.argmax(motion[moving])]]
    d = np.linalg.norm(base[moving] - base[chosen[0]], axis=1)
    for _ in range(min(count, len(moving)) - 1):
        nxt = int(np.argmax(d))
        chosen.append(moving[nxt])
        d = np.minimum(d, np.linalg.norm(base[moving] - base[moving[nxt]], axis=1))
    return np.array(chosen, np.int64)


@dataclass(frozen=True)
class ExampleCloner:
    """Feature matrix, weight functions and target key-model deltas, ready for runtime blending."""

    feature_ids: np.ndarray  # (f,)
    source_features: np.ndarray  # (3f,) s_B
    feature_matrix: np.ndarray  # (n, 3f) F
    weights: CardinalWeights
    target_base: np.ndarray  # (Vt, 3)
    target_deltas: np.ndarray  # (M, Vt * 3) T_i - T_B

    @classmethod
    def fit(cls, pairs: KeyPairs) -> ExampleCloner:
        """Preprocess key-model pairs (compositing, parameterisation, weight functions)."""
        pairs = with_composites(pairs)
        ids = pick_features(pairs.source_base, pairs.source) if pairs.feature_ids is None else pairs.feature_ids
        s_b = pairs.source_base[ids].reshape(-1).astype(np.float64)
        v = pairs.source[:, ids].reshape(len(pairs.source), -1) - s_b  # eq. 1
        # PCA of the displacement vectors about the base (which is the origin of the parameter space).
        _, sv, vt = np.linalg.svd(v, full_matrices=False)
        ev = sv**2
        keep = ev > PCA_THRESHOLD * ev[0] if len(ev) and ev[0] > 0 else np.zeros(len(ev), bool)
        if not keep.any():
            raise InputError("the source key-models do not move the feature points; give other key-models.")
        f = vt[keep]  # eq. 2
        p = np.vstack([np.zeros(f.shape[0]), v @ f.T])  # eq. 3, base first
        m = len(pairs.source)
        values = np.vstack([np.zeros(m), np.eye(m)])  # w_i(p_j) = delta_ij, all zero at the base
        w = CardinalWeights.fit(p, values)
        deltas = (pairs.target - pairs.target_base).reshape(m, -1).astype(np.float32)
        return cls(ids, s_b, f, w, pairs.target_base.astype(np.float32), deltas)

    def apply(self, frames: np.ndarray) -> np.ndarray:
        """Target frames (T, Vt, 3) for source frames (T, Vs, 3) in the head's frame."""
        d = frames[:, self.feature_ids].reshape(len(frames), -1) - self.source_features  # eq. 9
        p = d @ self.feature_matrix.T  # eq. 10
        w = self.weights(p).astype(np.float32)
        return self.target_base + (w @ self.target_deltas).reshape(len(frames), -1, 3)  # eq. 11
