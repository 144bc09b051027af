"""Camera's per-point arithmetic after its matrix products, compiled: bias, perspective divide, viewport, extent.

Camera.project and Camera.fit run over every vertex of every frame (the extraction, the triangle budget, the
verifier). As numpy, their arithmetic after the matrix products was a dozen passes over float64 temporaries,
most of a projection's time. The operations and their order are numpy's, so every value keeps its bits
(tests/core/test_camera.py keeps the numpy versions); the matrix products stay numpy's, whose BLAS sums in an
order of its own."""

from __future__ import annotations

import numba
import numpy as np


def to_pixels(eye: np.ndarray, ew: np.ndarray, bias: np.ndarray, w_bias: float, width: int,
              height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel xy (..., 2) with y down, NDC depth and clip w (...) from the matrix products of points: eye (..., 3)
    = points @ M[:3, :3].T and ew (...) = points @ M[3, :3], to which M[:3, 3] (bias) and M[3, 3] are added."""
    lead = ew.shape
    n = ew.size
    xy, z, w = np.empty(lead + (2,), np.float64), np.empty(lead, np.float64), np.empty(lead, np.float64)
    _to_pixels(np.ascontiguousarray(eye, np.float64).reshape(n, 3), np.ascontiguousarray(ew, np.float64).reshape(n),
               np.ascontiguousarray(bias, np.float64), float(w_bias), float(width), float(height),
               xy.reshape(n, 2), z.reshape(n), w.reshape(n))
    return xy, z, w


@numba.njit(cache=True, nogil=True)
def _to_pixels(eye, ew, bias, w_bias, width, height, xy, z, w):
    """to_pixels() of n points into xy (n, 2), z (n), w (n)."""
    for i in range(ew.shape[0]):
        wi = ew[i] + w_bias
        safe = wi if abs(wi) > 1e-12 else 1e-12
        xy[i, 0] = ((eye[i, 0] + bias[0]) / safe + 1) * 0.5 * width
        xy[i, 1] = (1 - (eye[i, 1] + bias[1]) / safe) * 0.5 * height
        z[i] = (eye[i, 2] + bias[2]) / safe
        w[i] = wi


def view_extent(eye: np.ndarray, bias: np.ndarray, ortho: bool) -> np.ndarray:
    """(2, 3): minima and maxima of (depth, x, y) over points seen from a camera, eye (N, 3) = points @
    view[:3, :3].T and bias = view[:3, 3]: x and y divided by depth unless ortho; NaN where a value is NaN, as
    numpy's min and max give."""
    out = np.empty((2, 3), np.float64)
    _view_extent(np.ascontiguousarray(eye, np.float64), np.ascontiguousarray(bias, np.float64), bool(ortho), out)
    return out


@numba.njit(cache=True, nogil=True)
def _view_extent(eye, bias, ortho, out):
    """view_extent() into out."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    nan = np.zeros(3, np.bool_)
    val = np.empty(3)
    for i in range(eye.shape[0]):
        depth = -(eye[i, 2] + bias[2])
        val[0] = depth
        if ortho:
            val[1] = eye[i, 0] + bias[0]
            val[2] = eye[i, 1] + bias[1]
        else:
            val[1] = (eye[i, 0] + bias[0]) / depth
            val[2] = (eye[i, 1] + bias[1]) / depth
        for k in range(3):
            if val[k] < lo[k]:
                lo[k] = val[k]
            if val[k] > hi[k]:
                hi[k] = val[k]
            if val[k] != val[k]:
                nan[k] = True
    for k in range(3):
        out[0, k] = np.nan if nan[k] else lo[k]
        out[1, k] = np.nan if nan[k] else hi[k]
