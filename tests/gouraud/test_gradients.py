"""The gradient geometry reproduces barycentric (Gouraud) interpolation, evaluated with the SVG paint rules."""

from __future__ import annotations

import numpy as np
import pytest

from converter.encode.gradients import (
    LinearGradients,
    barycentric,
    exact_gradients,
    gradient_color,
    gradient_parameter,
    vertex_ramps,
)

RNG = np.random.default_rng(4)


def random_triangles(n: int) -> np.ndarray:
    """n non-degenerate pixel-space triangles (n, 3, 2)."""
    tri = RNG.uniform(0, 512, (n, 3, 2))
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return tri[area2 > 50]


def sample_points(tri: np.ndarray, m: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """m random points inside each triangle and their barycentric weights."""
    w = RNG.dirichlet([1, 1, 1], (len(tri), m))
    return np.einsum("nmk,nkd->nmd", w, tri), w


def test_intensity_times_base_colour_is_exact():
    tri = random_triangles(500)
    base = RNG.uniform(0.2, 1.0, (len(tri), 1, 3))
    rgb = base * RNG.uniform(0.3, 1.0, (len(tri), 3, 1))  # Lambert: intensity x base colour
    g = exact_gradients(tri, rgb)
    pts, w = sample_points(tri)
    want = np.einsum("nmk,nkc->nmc", w, rgb)
    assert np.abs(gradient_color(pts, g) - want).max() < 1e-9
    assert g.residual.max() < 1e-9


def test_two_colour_blends_and_greys_are_exact():
    tri = random_triangles(300)
    c0, c1 = RNG.uniform(0, 1, (2, len(tri), 1, 3))
    s = RNG.uniform(0, 1, (len(tri), 3, 1))
    rgb = c0 * (1 - s) + c1 * s  # any colours on a line in RGB
    g = exact_gradients(tri, rgb)
    pts, w = sample_points(tri)
    assert np.abs(gradient_color(pts, g) - np.einsum("nmk,nkc->nmc", w, rgb)).max() < 1e-9


def test_general_rgb_error_is_the_reported_residual_and_optimal():
    tri = random_triangles(300)
    rgb = RNG.uniform(0, 1, (len(tri), 3, 3))  # three unrelated colours: rank 2, not drawable by one gradient
    g = exact_gradients(tri, rgb)
    # The interpolated field's error is affine, so its maximum sits at a vertex: the reported residual.
    vert = gradient_color(tri, g)
    assert np.allclose(np.abs(vert - rgb).max(axis=(1, 2)), g.residual, atol=1e-9)
    assert g.residual.max() > 0.01
    # Rank-1 (SVD) fit: no other colour axis through the mean does better in the least-squares sense.
    dev = rgb - rgb.mean(1, keepdims=True)
    best = ((vert - rgb) ** 2).sum(axis=(1, 2))
    for _ in range(20):
        axis = RNG.normal(size=(len(tri), 1, 3))
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        proj = (dev * axis).sum(-1, keepdims=True) * axis
        assert (((proj - dev) ** 2).sum(axis=(1, 2)) >= best - 1e-9).all()


def test_degenerate_and_uniform_triangles_paint_the_mean():
    tri = np.array([[[0, 0], [10, 0], [20, 0]], [[0, 0], [10, 0], [0, 10]]], float)
    rgb = np.array([[[1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0.5, 0.5, 0.5]] * 3])
    g = exact_gradients(tri, rgb)
    assert np.isfinite(g.start).all() and np.isfinite(g.end).all()
    assert np.allclose(g.start_rgb, g.end_rgb)
    assert np.allclose(g.start_rgb, rgb.mean(1))
    assert np.isclose(g.residual[0], 2 / 3) and g.residual[1] == 0


@pytest.mark.parametrize("shape", [(7,), (2, 5)])
def test_vertex_ramps_are_barycentric_weights(shape):
    tri = random_triangles(40)[: int(np.prod(shape))].reshape(*shape, 3, 2)
    start, foot = vertex_ramps(tri)
    flat = tri.reshape(-1, 3, 2)
    pts, w = sample_points(flat)
    s, f = start.reshape(-1, 3, 2), foot.reshape(-1, 3, 2)
    # Each ramp's alpha runs 1 at its vertex to 0 at the opposite edge: 1 - gradient parameter.
    alpha = np.stack([1 - gradient_parameter(pts, s[:, i], f[:, i]) for i in range(3)], axis=-1)
    assert np.abs(alpha - w).max() < 1e-9
    rgb = RNG.uniform(0, 1, (len(flat), 3, 3))  # the premultiplied sum of the three layers is Gouraud
    assert np.allclose(np.einsum("nmk,nkc->nmc", alpha, rgb), np.einsum("nmk,nkc->nmc", w, rgb))


def test_gradient_parameter_pads_outside_the_axis():
    g = LinearGradients(np.array([[0.0, 0.0]]), np.array([[10.0, 0.0]]), np.array([[0.0, 0, 0]]),
                        np.array([[1.0, 1, 1]]), np.zeros(1))
    pts = np.array([[[-5.0, 3.0], [5.0, -7.0], [25.0, 1.0]]])
    assert np.allclose(gradient_color(pts, g)[0, :, 0], [0.0, 0.5, 1.0])


def test_barycentric_of_vertices():
    tri = random_triangles(10)
    assert np.allclose(barycentric(tri, tri), np.eye(3)[None].repeat(len(tri), 0))
