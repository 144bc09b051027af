"""Per-frame robust affine fits of a point set to its neutral shape (the rigid factoring's head and bands).

Each frame's 2x3 map is iteratively reweighted least squares with Cauchy weights, so that lips and a jaw moving
on their own barely pull a fit of the whole skin. The loop is compiled (numba, nogil, frames split over a few
threads) and reads the points straight from the Sheet's (T, V, 2) array: the numpy version gathered them into a
float64 copy and made ~10 passes over (T, n, 2) temporaries per iteration, a noticeable share of a long
conversion.
"""

from __future__ import annotations

import numba
import numpy as np

from converter.encode import parallel

HUBER_PX = 1.0  # scale of the robust (Cauchy) weights in the affine fit
FIT_ITERATIONS = 3
RIDGE = 1e-9  # added to the normal equations' diagonal: a fit of collinear points still solves


def fit_affine(ref: np.ndarray, xy: np.ndarray, verts: np.ndarray | None = None) -> np.ndarray:
    """Per frame the 2x3 affine map (T, 2, 3) taking ref (n, 2) closest to the points xy (T, n, 2), or to
    xy[:, verts] when verts (n,) is given (xy then (T, V, 2)), robust to local motion."""
    idx = np.arange(xy.shape[1], dtype=np.int64) if verts is None else np.asarray(verts, np.int64)
    t, n = xy.shape[0], len(idx)
    ref = np.ascontiguousarray(ref, np.float64)
    if n < 3 or np.linalg.matrix_rank(ref - ref.mean(0), tol=1e-6) < 2:
        out = np.zeros((t, 2, 3))
        out[:, 0, 0] = out[:, 1, 1] = 1.0
        out[:, :, 2] = np.asarray(xy[:, idx], np.float64).mean(axis=1) - ref.mean(axis=0)
        return out
    out = np.empty((t, 2, 3))
    if t:
        parallel.threaded(_fit_frames, t, ref, np.ascontiguousarray(xy), idx, FIT_ITERATIONS, HUBER_PX, out)
    return out


@numba.njit(cache=True, nogil=True)
def _solve3(m: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:  # pragma: no cover - compiled
    """x (3, 2) = m^-1 b for m (3, 3), b (3, 2) by Gaussian elimination with partial pivoting (m, b overwritten)."""
    for c in range(3):
        p = c
        for r in range(c + 1, 3):
            if abs(m[r, c]) > abs(m[p, c]):
                p = r
        if p != c:
            for k in range(3):
                m[c, k], m[p, k] = m[p, k], m[c, k]
            for k in range(2):
                b[c, k], b[p, k] = b[p, k], b[c, k]
        for r in range(c + 1, 3):
            f = m[r, c] / m[c, c]
            for k in range(c, 3):
                m[r, k] -= f * m[c, k]
            for k in range(2):
                b[r, k] -= f * b[c, k]
    for c in range(2, -1, -1):
        for k in range(2):
            s = b[c, k]
            for j in range(c + 1, 3):
                s -= m[c, j] * x[j, k]
            x[c, k] = s / m[c, c]


@numba.njit(cache=True, nogil=True)
def _fit_frames(ref, xy, idx, iterations, huber, out, first, stop):  # pragma: no cover - compiled
    """fit_affine for frames first..stop: each iteration weights every point by its residual under the previous
    solution (all 1 at first), solves the weighted normal equations and keeps the solution.

    The sums are scalars, not the cells of m and b: the compiler cannot tell those arrays from the points', so it
    stored and reloaded every cell at every point (a noticeable share of the 128k-triangle face's writer). Each sum
    adds the same
    terms in the same order either way."""
    n = len(idx)
    m = np.empty((3, 3))
    b = np.empty((3, 2))
    sol = np.zeros((3, 2))
    for t in range(first, stop):
        for it in range(iterations):
            s00 = s01 = s02 = s11 = s12 = s22 = 0.0
            b00 = b01 = b10 = b11 = b20 = b21 = 0.0
            a00, a10, a20 = sol[0, 0], sol[1, 0], sol[2, 0]
            a01, a11, a21 = sol[0, 1], sol[1, 1], sol[2, 1]
            for i in range(n):
                d0, d1 = ref[i, 0], ref[i, 1]
                x, y = xy[t, idx[i], 0], xy[t, idx[i], 1]
                w = 1.0
                if it:
                    ex = d0 * a00 + d1 * a10 + a20 - x
                    ey = d0 * a01 + d1 * a11 + a21 - y
                    q = np.sqrt(ex * ex + ey * ey) / huber
                    w = 1.0 / (1.0 + q * q)
                s00 += w * d0 * d0
                s01 += w * d0 * d1
                s02 += w * d0
                s11 += w * d1 * d1
                s12 += w * d1
                s22 += w
                b00 += w * d0 * x
                b01 += w * d0 * y
                b10 += w * d1 * x
                b11 += w * d1 * y
                b20 += w * x
                b21 += w * y
            m[0, 0], m[0, 1], m[0, 2] = s00, s01, s02
            m[1, 0], m[1, 1], m[1, 2] = s01, s11, s12
            m[2, 0], m[2, 1], m[2, 2] = s02, s12, s22
            b[0, 0], b[0, 1], b[1, 0], b[1, 1], b[2, 0], b[2, 1] = b00, b01, b10, b11, b20, b21
            for k in range(3):
                m[k, k] += RIDGE
            _solve3(m, b, sol)
        for r in range(2):
            for k in range(3):
                out[t, r, k] = sol[k, r]
