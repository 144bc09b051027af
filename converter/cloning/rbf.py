"""Radial basis functions: the multiquadric volume morph (chapter 11.3) and cardinal weight functions (seed 000)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist

from converter.errors import InputError


@dataclass(frozen=True)
class VolumeMorph:
    """F(x) = sum_j w_j sqrt(|x - c_j|^2 + s_j^2) + affine(x), fitted with ridge regularisation (11.1-11.3)."""

    centres: np.ndarray  # (N, 3)
    s2: np.ndarray  # (N,) squared multiquadric widths
    weights: np.ndarray  # (N + 4, 3): radial weights then the affine part

    @classmethod
    def fit(cls, source: np.ndarray, target: np.ndarray, lam: float = 1e-6) -> VolumeMorph:
        """Train on sparse correspondences source[i] -> target[i]; lam is relative to the kernel scale."""
        source = np.asarray(source, np.float64)
        target = np.asarray(target, np.float64)
        check_points(source, "source")
        check_points(target, "target")
        d = cdist(source, source)
        np.fill_diagonal(d, np.inf)
        s2 = d.min(axis=1) ** 2  # 11.2: distance to the nearest other centre
        h = np.sqrt(cdist(source, source, "sqeuclidean") + s2[None, :])
        p = np.hstack([np.ones((len(source), 1)), source])
        n = len(source)
        # The affine part keeps far-away points (the back of the head) on a sensible global fit; the
        # radial part's side conditions (P^T w = 0) make the whole system square and solvable.
        a = np.zeros((n + 4, n + 4))
        a[:n, :n] = h + lam * np.abs(h).mean() * np.eye(n)
        a[:n, n:] = p
        a[n:, :n] = p.T
        rhs = np.vstack([target, np.zeros((4, 3))])
        try:
            w = np.linalg.solve(a, rhs)
        except np.linalg.LinAlgError:
            raise InputError("the correspondences are degenerate (all on one plane or repeated); add points "
                             "spread over the face.") from None
        if not np.isfinite(w).all():
            raise InputError("the correspondences are degenerate; add points spread over the face.")
        return cls(source, s2, w)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Morph points (n, 3)."""
        points = np.asarray(points, np.float64)
        h = np.sqrt(cdist(points, self.centres, "sqeuclidean") + self.s2[None, :])
        n = len(self.centres)
        return h @ self.weights[:n] + self.weights[n] + points @ self.weights[n + 1:]


def check_points(points: np.ndarray, what: str) -> None:
    """Raise InputError unless there are >= 4 distinct, finite, non-coplanar points."""
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise InputError(f"need at least 4 {what} correspondence points, got {len(points)}; add more.")
    if not np.isfinite(points).all():
        raise InputError(f"a {what} correspondence point is not a finite number; fix the file.")
    scale = np.ptp(points, axis=0).max()
    d = cdist(points, points)
    np.fill_diagonal(d, np.inf)
    if scale <= 0 or d.min() < 1e-6 * scale:
        raise InputError(f"two {what} correspondence points coincide; each point must be distinct.")
    sv = np.linalg.svd(points - points.mean(0), compute_uv=False)
    if sv[2] < 1e-3 * sv[0]:
        raise InputError(f"the {what} correspondence points all lie on one plane or line; add points off it.")


def cubic_bspline(r: np.ndarray) -> np.ndarray:
    """The uniform cubic B-spline centred at 0 (support |r| < 2, value 2/3 at 0)."""
    r = np.abs(r)
    return np.where(r < 1, (4 - 6 * r**2 + 3 * r**3) / 6, np.where(r < 2, (2 - r) ** 3 / 6, 0.0))


@dataclass(frozen=True)
class CardinalWeights:
    """Weight functions w_i(p) = sum_l a_il A_l(p) + sum_j r_ji R_j(p) that interpolate cardinal data (eq. 4-8)."""

    centres: np.ndarray  # (M, n) parameter vectors of the examples
    dilation: np.ndarray  # (M,) alpha_j: separation to the nearest other example
    linear: np.ndarray  # (n + 1, K) a: constant then one row per parameter component
    radial: np.ndarray  # (M, K) r

    @classmethod
    def fit(cls, params: np.ndarray, values: np.ndarray) -> CardinalWeights:
        """Fit K weight functions to values (M, K) at example parameters (M, n)."""
        params = np.asarray(params, np.float64)
        values = np.asarray(values, np.float64)
        a_mat = np.hstack([np.ones((len(params), 1)), params])
        linear = np.linalg.lstsq(a_mat, values, rcond=None)[0]  # eq. 5, least squares
        residual = values - a_mat @ linear  # eq. 6
        d = cdist(params, params)
        np.fill_diagonal(d, np.inf)
        dilation = d.min(axis=1)
        if not (dilation > 0).all():
            raise InputError("two key-models have the same feature-point displacements; remove the duplicate.")
        r_mat = cubic_bspline(cdist(params, params) / dilation[None, :])  # R[i, j] = R_j(p_i)
        radial = np.linalg.lstsq(r_mat, residual, rcond=None)[0]  # eq. 8
        return cls(params, dilation, linear, radial)

    def __call__(self, params: np.ndarray) -> np.ndarray:
        """Weights (T, K) at parameter vectors (T, n)."""
        params = np.atleast_2d(np.asarray(params, np.float64))
        r = cubic_bspline(cdist(params, self.centres) / self.dilation[None, :])
        return self.linear[0] + params @ self.linear[1:] + r @ self.radial
