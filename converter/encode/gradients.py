"""Gradient geometry for Gouraud-shaded SVG: the exact one-gradient fit and the chapter's three alpha ramps.

Everything here is pure numpy over arbitrary leading axes (frames, triangles): triangles are (..., 3, 2) pixel
positions, vertex colours (..., 3, 3) display-space RGB 0..1.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

_FLAT_RANGE = 1e-6  # colour spread below this paints one solid colour
_MIN_AREA2 = 1e-9  # twice the pixel area under which a triangle counts as degenerate


class LinearGradients(NamedTuple):
    """userSpaceOnUse linearGradient parameters: axis start/end (..., 2), stop colours (..., 3), fit error (...)."""

    start: np.ndarray
    end: np.ndarray
    start_rgb: np.ndarray
    end_rgb: np.ndarray
    residual: np.ndarray  # max |fitted - given| vertex colour channel; 0 when the colours are collinear in RGB


def exact_gradients(tri_xy: np.ndarray, tri_rgb: np.ndarray) -> LinearGradients:
    """One linear gradient per triangle that reproduces barycentric colour interpolation.

    A colour affine over the triangle is drawn exactly by one linear gradient when its three vertex colours lie
    on a line in RGB (vertex intensity x one base colour is the common case). In general the colour deviations
    from the mean are replaced by their best rank-1 approximation (SVD, least squares over the triangle's area),
    so the gradient follows the principal colour axis and `residual` says how far a vertex colour moved.
    """
    xy = np.asarray(tri_xy, np.float64)
    rgb = np.asarray(tri_rgb, np.float64)
    p_mean = xy.mean(axis=-2)
    c_mean = rgb.mean(axis=-2)
    dev = rgb - c_mean[..., None, :]  # (..., vertex, channel); columns sum to zero
    u_, s_, vt = np.linalg.svd(dev)
    t = u_[..., :, 0] * s_[..., None, 0]  # per-vertex scalar along the principal colour axis, sums to zero
    axis = vt[..., 0, :]  # unit colour direction
    flip = axis.sum(axis=-1) < 0  # orient towards brighter so the sign is deterministic
    axis = np.where(flip[..., None], -axis, axis)
    t = np.where(flip[..., None], -t, t)

    # t is affine over the triangle: t(x) = g . (x - p_mean); solve g from two edges.
    e = xy[..., 1:, :] - xy[..., :1, :]  # (..., 2, 2) rows are edge vectors
    dt = t[..., 1:] - t[..., :1]
    det = e[..., 0, 0] * e[..., 1, 1] - e[..., 0, 1] * e[..., 1, 0]
    ok = np.abs(det) > _MIN_AREA2
    safe = np.where(ok, det, 1.0)
    gx = (dt[..., 0] * e[..., 1, 1] - dt[..., 1] * e[..., 0, 1]) / safe
    gy = (e[..., 0, 0] * dt[..., 1] - e[..., 1, 0] * dt[..., 0]) / safe
    g = np.stack([gx, gy], axis=-1)
    g2 = (g * g).sum(axis=-1)
    t_lo, t_hi = t.min(axis=-1), t.max(axis=-1)
    flat = ~ok | (t_hi - t_lo < _FLAT_RANGE) | (g2 <= 0)
    g2s = np.where(flat, 1.0, g2)
    start = p_mean + g * (t_lo / g2s)[..., None]
    end = p_mean + g * (t_hi / g2s)[..., None]
    start_rgb = c_mean + t_lo[..., None] * axis
    end_rgb = c_mean + t_hi[..., None] * axis
    # Degenerate or uniform triangles: a one-pixel axis with both stops at the mean colour (a solid fill).
    start = np.where(flat[..., None], p_mean, start)
    end = np.where(flat[..., None], p_mean + np.array([1.0, 0.0]), end)
    start_rgb = np.where(flat[..., None], c_mean, start_rgb)
    end_rgb = np.where(flat[..., None], c_mean, end_rgb)
    grads = LinearGradients(start, end, np.clip(start_rgb, 0, 1), np.clip(end_rgb, 0, 1), np.zeros(p_mean.shape[:-1]))
    # What is drawn is affine between the (clipped) stops, so its largest error sits at a vertex.
    drawn = gradient_color(xy, grads)
    return grads._replace(residual=np.abs(drawn - rgb).max(axis=(-2, -1)))


def vertex_ramps(tri_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chapter's per-vertex gradient axes: from each vertex (..., 3, 2) to its foot on the opposite edge.

    An alpha going 1 -> 0 along this axis equals the vertex's barycentric weight, so the three ramps sum to 1.
    """
    xy = np.asarray(tri_xy, np.float64)
    a = xy
    b = np.roll(xy, -1, axis=-2)
    c = np.roll(xy, -2, axis=-2)
    edge = c - b
    l2 = (edge * edge).sum(axis=-1)
    s = ((a - b) * edge).sum(axis=-1) / np.where(l2 > 0, l2, 1.0)
    foot = b + s[..., None] * edge
    degenerate = ((foot - a) ** 2).sum(axis=-1) < 1e-12
    foot = np.where(degenerate[..., None], a + np.array([1.0, 0.0]), foot)
    return a, foot


def gradient_parameter(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """The SVG linearGradient parameter of points (..., N, 2) for an axis (..., 2), padded to 0..1."""
    d = end - start
    d2 = (d * d).sum(axis=-1)
    s = ((points - start[..., None, :]) * d[..., None, :]).sum(axis=-1) / np.where(d2 > 0, d2, 1.0)[..., None]
    return np.clip(s, 0.0, 1.0)


def gradient_color(points: np.ndarray, grad: LinearGradients) -> np.ndarray:
    """Colour (..., N, 3) an SVG renderer paints at points (..., N, 2) for two-stop gradients (pad spread)."""
    s = gradient_parameter(points, grad.start, grad.end)[..., None]
    return grad.start_rgb[..., None, :] * (1 - s) + grad.end_rgb[..., None, :] * s


def barycentric(points: np.ndarray, tri_xy: np.ndarray) -> np.ndarray:
    """Barycentric weights (..., N, 3) of points (..., N, 2) in triangles (..., 3, 2)."""
    a, b, c = (tri_xy[..., i, None, :] for i in range(3))
    v0, v1, v2 = b - a, c - a, points - a
    d00 = (v0 * v0).sum(-1)
    d01 = (v0 * v1).sum(-1)
    d11 = (v1 * v1).sum(-1)
    d20 = (v2 * v0).sum(-1)
    d21 = (v2 * v1).sum(-1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - v - w, v, w], axis=-1)
