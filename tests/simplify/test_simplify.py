"""Triangle budget: one simplified topology on a subset of the vertices, animation carried over, error reported."""

import numpy as np
import pytest

from converter import simplify
from converter.convert import convert_animation
from converter.errors import InputError
from converter.options import ConversionOptions, Report
from converter.verify import verify_animation
from verify.ictface import ict_face


@pytest.fixture(scope="module")
def face(shared_data):  # the ICT head
    return ict_face(16, front=3.0)


def test_budget_keeps_a_vertex_subset_and_every_frame(face):
    report = Report()
    out = simplify.simplify(face, 1200, report, options=ConversionOptions(max_triangles=1200))
    assert 600 < out.n_faces <= 1200 and out.n_frames == face.n_frames
    # Every simplified vertex is an original vertex at every frame (half-edge collapse keeps a subset).
    orig = {tuple(np.round(v, 5)) for v in face.frames[5]}
    assert all(tuple(np.round(v, 5)) in orig for v in out.frames[5])
    # Parts keep their identity and get a share of the budget.
    assert set(out.part_ids.tolist()) == set(face.part_ids.tolist())
    assert report.figures["budget_deviation_px"] >= report.figures["budget_deviation_mean_px"] > 0
    assert report.counts["budget_triangles"] == out.n_faces
    assert report.counts["budget_dropped_never_facing"] > 0


@pytest.mark.slow
def test_tighter_budget_deviates_more(face):
    opts = ConversionOptions
    loose, tight = Report(), Report()
    simplify.simplify(face, 3000, loose, options=opts(max_triangles=3000))
    simplify.simplify(face, 400, tight, options=opts(max_triangles=400))
    assert tight.figures["budget_deviation_mean_px"] > loose.figures["budget_deviation_mean_px"]


def test_motion_attributes_ignore_head_motion_and_see_the_jaw(face):
    attrs = simplify.motion_attributes(face.frames)
    moving = np.linalg.norm(attrs, axis=1)
    # The face turns (rigid motion everywhere) but only the expressive regions deform.
    assert np.percentile(moving, 95) > 10 * max(np.percentile(moving, 20), 1e-9)
    mouth = np.unique(face.faces[face.part_ids == [p.name for p in face.parts].index("mouth")])
    assert np.median(moving[mouth]) > 3 * np.median(moving)


def test_simplify_with_attributes_binding_works_where_the_wrapper_does_not():
    from verify.synth import grid

    v, f = grid(12)
    fn = simplify._simplify_with_attributes()
    attrs = np.zeros((len(v), 2), np.float32)
    out = simplify._part_simplify(fn, v.astype(np.float32), attrs, np.zeros(len(v), np.uint8), f, 40)
    assert 0 < len(out) <= 60 and out.max() < len(v)


@pytest.mark.slow
def test_converted_budget_output_verifies(face):
    result = convert_animation(face, ConversionOptions(size=128, max_triangles=800, occlusion=False))
    assert result.report.counts["budget_triangles"] <= 800
    assert result.report.counts["paths"] <= 800
    assert "budget_deviation_px" in result.report.figures
    simplified = simplify.simplify(face, 800, Report(), options=ConversionOptions(size=128, max_triangles=800,
                                                                                   occlusion=False))
    assert verify_animation(result.data, simplified).ok


def test_too_small_budget_is_refused(face):
    with pytest.raises(InputError, match="at least 4"):
        simplify.simplify(face, 2, Report())


def _long_deforming_grid(n_frames: int) -> np.ndarray:
    """(T, V, 3): a 12x12 grid turning about y while its upper half bulges and sways (two deformations)."""
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 12), np.linspace(-1, 1, 12)), -1).reshape(-1, 2)
    rest = np.column_stack([g, np.zeros(len(g))])
    t = np.arange(n_frames)[:, None]
    upper = (g[:, 1] > 0).astype(float)[None]
    out = np.repeat(rest[None], n_frames, axis=0)
    out[..., 2] += 0.3 * upper * np.sin(t / 17.0)  # bulge
    out[..., 0] += 0.1 * upper * g[None, :, 1] * np.cos(t / 29.0)  # sway
    a = 0.4 * np.sin(t[:, 0] / 50.0)
    rot = np.zeros((n_frames, 3, 3))
    rot[:, 0, 0] = rot[:, 2, 2] = np.cos(a)
    rot[:, 0, 2], rot[:, 2, 0], rot[:, 1, 1] = np.sin(a), -np.sin(a), 1.0
    return np.einsum("tij,tvj->tvi", rot, out).astype(np.float32)


def test_rigid_residual_in_frame_blocks_equals_each_frame_fitted_alone():
    frames = _long_deforming_grid(3 * simplify.FRAME_BLOCK + 5)
    blocked = simplify.rigid_residual(frames)
    for k in (1, simplify.FRAME_BLOCK, len(frames) - 1):
        alone = simplify.rigid_residual(frames[[0, k]])[1]
        np.testing.assert_allclose(blocked[k], alone, atol=1e-9)


def test_long_clips_read_motion_from_evenly_spaced_frames(monkeypatch):
    monkeypatch.setattr(simplify, "MOTION_FRAMES", 64)  # the default (512) works the same, only slower to test
    frames = _long_deforming_grid(400)
    sampled = np.linalg.norm(simplify.motion_attributes(frames), axis=1)
    monkeypatch.setattr(simplify, "MOTION_FRAMES", len(frames))
    every = np.linalg.norm(simplify.motion_attributes(frames), axis=1)
    np.testing.assert_allclose(sampled, every, rtol=0.05, atol=0.02 * every.max())
    assert every.max() > 0.01  # the grid deforms: the comparison is not of zeros


def numpy_rigid_residual(frames, rounds=3):
    """simplify.rigid_residual as numpy computed it before it was compiled (the reference)."""
    ref = np.asarray(frames[0], np.float64)
    out = np.empty(frames.shape, np.float64)
    for s in range(0, len(frames), simplify.FRAME_BLOCK):
        x = np.asarray(frames[s:s + simplify.FRAME_BLOCK], np.float64)
        weight = np.ones(x.shape[:2])
        for _ in range(rounds):
            wsum = weight.sum(axis=1, keepdims=True)[..., None]
            c_ref = (weight[..., None] * ref[None]).sum(axis=1, keepdims=True) / wsum
            c_fr = (weight[..., None] * x).sum(axis=1, keepdims=True) / wsum
            xc = x - c_fr
            h = np.swapaxes(weight[..., None] * xc, 1, 2) @ (ref[None] - c_ref)
            u, _, vt = np.linalg.svd(h)
            fix = np.ones((len(x), 3))
            fix[:, 2] = np.sign(np.linalg.det(u @ vt))
            rot = (u * fix[:, None, :]) @ vt
            residual = xc @ rot + c_ref - ref[None]
            r = np.linalg.norm(residual, axis=-1)
            weight = (r <= np.median(r, axis=1, keepdims=True)).astype(np.float64)
        out[s:s + simplify.FRAME_BLOCK] = residual
    return out


def test_compiled_rigid_residual_is_the_numpy_one():
    # Sums in another order than numpy's (and BLAS's), so equal to rounding, not bit for bit; the trimmed fit
    # picks the same vertices.
    frames = _long_deforming_grid(2 * simplify.FRAME_BLOCK + 3)
    got, want = simplify.rigid_residual(frames), numpy_rigid_residual(frames)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.abs(want).max() > 0.05  # the grid deforms: not a comparison of zeros


def test_compiled_deviation_is_numpys():
    rng = np.random.default_rng(3)
    b, v, vs, n = 4, 300, 40, 120
    xy0, xy1 = rng.uniform(0, 256, (b, v, 2)), rng.uniform(0, 256, (b, vs, 2))
    verts = rng.choice(v, n, replace=False)
    corner = rng.integers(0, vs, (n, 3)).astype(np.int32)
    bary = rng.dirichlet(np.ones(3), n)
    shown = rng.random((b, n)) < 0.7
    follow = sum(bary[None, :, c, None] * xy1[:, corner[:, c]] for c in range(3))
    want = np.where(shown, np.linalg.norm(follow - xy0[:, verts], axis=-1), 0.0)
    got = np.empty((b, n))
    simplify._deviation(xy0, xy1, verts, corner, bary, shown, got)
    assert np.array_equal(got, want)
