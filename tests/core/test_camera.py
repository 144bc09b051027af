"""Projection against hand-computed values, camera fitting, and whole-triangle culling on a cube."""

import numpy as np
import pytest

from converter.camera import Camera, frustum, look_at, orthographic
from converter.errors import InputError
from converter.extract import cull, extract, fit_camera


def test_perspective_projection_matches_hand_computation():
    view = look_at(np.array([0.0, 0.0, 10.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    cam = Camera(view, frustum(-1, 1, -1, 1, 1, 100), 200, 100)
    xy, z, w = cam.project(np.array([[1.0, 0.5, 0.0], [0.0, 0.0, 0.0]]))
    # eye space (1, 0.5, -10): ndc x = 2n/(r-l) * x / -z = 0.1, ndc y = 0.05; pixels: y grows downwards.
    assert xy[0] == pytest.approx([(0.1 + 1) / 2 * 200, (1 - 0.05) / 2 * 100])
    assert xy[1] == pytest.approx([100, 50])
    assert w[0] == pytest.approx(10.0)
    # ndc z of eye depth 10 for near 1, far 100: (f+n)/(f-n) - 2fn/((f-n) d)
    assert z[0] == pytest.approx(101 / 99 - 200 / (99 * 10))


def test_orthographic_projection_matches_hand_computation():
    view = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    cam = Camera(view, orthographic(-2, 2, -1, 1, 0.1, 10), 400, 200, True)
    xy, _, w = cam.project(np.array([[1.0, -0.5, 3.0]]))
    assert xy[0] == pytest.approx([(0.5 + 1) / 2 * 400, (1 + 0.5) / 2 * 200])
    assert w[0] == pytest.approx(1.0)


def test_matrices_round_trip_through_json():
    cam = Camera.fit(np.random.default_rng(0).normal(size=(3, 50, 3)), size=64, yaw=30, pitch=-10)
    again = Camera.from_json(cam.to_json())
    assert np.array_equal(again.view, cam.view) and np.array_equal(again.projection, cam.projection)


@pytest.mark.parametrize("yaw,pitch,ortho", [(0, 0, False), (35, 10, False), (-90, 0, True), (180, 60, False)])
def test_fit_frames_every_vertex_of_every_frame(yaw, pitch, ortho):
    rng = np.random.default_rng(1)
    frames = rng.normal(size=(5, 200, 3)) * [3, 1, 0.5] + rng.normal(size=(5, 1, 3))
    cam = Camera.fit(frames, size=256, yaw=yaw, pitch=pitch, ortho=ortho)
    xy, z, w = cam.project(frames)
    assert (w > 0).all() and (np.abs(z) < 1).all()
    assert xy.min() >= 0 and xy.max() <= 256
    # The fit is tight: the larger extent fills the view up to the margin.
    extent = max(np.ptp(xy[..., 0]), np.ptp(xy[..., 1]))
    assert extent > 256 * 0.85


def test_yaw_90_looks_from_positive_x():
    frames = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 0, 1]]])
    cam = Camera.fit(frames, size=100, yaw=90)
    assert cam.eye_position()[0] > 1 and abs(cam.eye_position()[2]) < 1e-6 + 0.5


def test_bad_camera_options_are_input_errors():
    with pytest.raises(InputError):
        Camera.fit(np.zeros((1, 3, 3)), size=4)
    with pytest.raises(InputError):
        Camera.fit(np.zeros((1, 3, 3)), fov=0)


def test_cube_front_view_sees_exactly_the_front_face(cube):
    cam = fit_camera(cube, size=128)
    xy, z, w = cam.project(cube.frames)
    vis = cull(xy, z, w, cube.faces, 128, 128)
    centroids = cube.frames[0][cube.faces].mean(1)
    front = np.isclose(centroids[:, 2], 1.0)
    assert np.array_equal(vis[0], front)
    # Rotating by 20 degrees a frame brings the +x side into view from frame 1 on.
    side = np.isclose(centroids[:, 0], -1.0)
    assert vis[1][side].all() and not vis[0][side].any()


def test_frustum_culling_drops_whole_triangles_outside(cube):
    frames = np.array(cube.frames)
    cam = fit_camera(cube, size=128)
    frames[2] += np.array([100.0, 0, 0], np.float32)  # frame 2 leaves the view entirely
    xy, z, w = cam.project(frames)
    vis = cull(xy, z, w, cube.faces, 128, 128)
    assert vis[0].any() and not vis[2].any()


def test_extract_occlusion_keeps_only_seen_triangles(cube):
    from converter.animation import FaceAnimation

    # Two cubes, one hidden right behind the other from the front: its front faces are never seen.
    f = cube.frames[:1]
    frames = np.concatenate([f, f * 0.5 + np.array([0, 0, -3.0], np.float32)], axis=1)
    faces = np.concatenate([cube.faces, cube.faces + 8])
    anim = FaceAnimation(frames, faces, np.zeros(len(faces), np.int32), cube.parts, 10.0)
    cam = fit_camera(anim, size=96)
    sheet = extract(anim, cam, occlusion=True)
    assert sheet.kept[:12].sum() == 2  # the big cube's front face
    assert not sheet.kept[12:].any()  # the hidden cube's front face faces us but is covered
    assert sheet.info["triangles_never_visible"] == 22
    no_occ = extract(anim, cam, occlusion=False)
    assert no_occ.kept[12:].sum() == 2


def test_fit_in_chunks_frames_exactly_as_in_one_piece(monkeypatch):
    import converter.camera as camera_module

    rng = np.random.default_rng(3)
    frames = (rng.normal(size=(9, 1001, 3)) * [1.0, 2.0, 0.5] + [0.0, 0.0, 3.0]).astype(np.float32)
    for ortho in (False, True):
        whole = Camera.fit(frames, yaw=15, pitch=5, ortho=ortho)
        monkeypatch.setattr(camera_module, "FIT_CHUNK", 977)  # chunks that split frames unevenly
        chunked = Camera.fit(frames, yaw=15, pitch=5, ortho=ortho)
        monkeypatch.setattr(camera_module, "FIT_CHUNK", 1 << 20)
        np.testing.assert_array_equal(whole.view, chunked.view)
        np.testing.assert_array_equal(whole.projection, chunked.projection)
        xy, _, _ = whole.project(frames.reshape(-1, 3))
        assert xy.min() >= 0 and xy.max() <= whole.width  # every vertex of every frame is in view


def test_culling_matches_its_per_corner_definition_on_random_triangles():
    # Front (negative signed area with y down), every corner in front of the eye (w > 0), and not all three
    # corners beyond one side of the view volume; NaN corners count as failing every comparison.
    rng = np.random.default_rng(5)
    t, v, f, size = 6, 300, 900, 64
    faces = rng.integers(0, v, (f, 3)).astype(np.int32)
    xy = rng.uniform(-40, 104, (t, v, 2))
    z, w = rng.uniform(-1.3, 1.3, (t, v)), rng.uniform(-0.5, 2.0, (t, v))
    xy[0, :7], z[1, :7], w[2, :7] = np.nan, np.nan, np.nan
    corner = lambda a: a[:, faces]  # noqa: E731
    tx, ty, tz, tw = corner(xy[..., 0]), corner(xy[..., 1]), corner(z), corner(w)
    area2 = ((tx[..., 1] - tx[..., 0]) * (ty[..., 2] - ty[..., 0])
             - (ty[..., 1] - ty[..., 0]) * (tx[..., 2] - tx[..., 0]))
    outside = ((tx < 0).all(-1) | (tx > size).all(-1) | (ty < 0).all(-1) | (ty > size).all(-1)
               | (tz < -1).all(-1) | (tz > 1).all(-1))
    expected = (area2 < 0) & (tw > 0).all(-1) & ~outside
    got = cull(xy, z, w, faces, size, size)
    assert 0 < expected.sum() < expected.size
    assert np.array_equal(got, expected)


@pytest.mark.parametrize("n", [1, 5, 1023, 1024, 1025, 3 * 1024 + 7])
def test_extent_equals_numpy_min_max(n):
    from converter.camera import _extent

    pts = np.random.default_rng(n).normal(size=(n, 3)).astype(np.float32)
    lo, hi = _extent(pts)
    assert lo.dtype == np.float64
    assert np.array_equal(lo, pts.min(axis=0)) and np.array_equal(hi, pts.max(axis=0))


def numpy_cull(xy, ndc_z, w, faces, width, height):
    """extract.cull as numpy computed it before it was compiled (the reference)."""
    x, y = xy[..., 0], xy[..., 1]
    f0, f1, f2 = faces[:, 0], faces[:, 1], faces[:, 2]
    ax, ay = np.take(x, f0, axis=-1), np.take(y, f0, axis=-1)
    x1, y1, x2, y2 = (np.take(a, f, axis=-1) for a, f in ((x, f1), (y, f1), (x, f2), (y, f2)))
    area2 = (x1 - ax) * (y2 - ay) - (y1 - ay) * (x2 - ax)
    bits = np.zeros(x.shape, np.uint8)
    for i, out in enumerate((x < 0, x > width, y < 0, y > height, ndc_z < -1, ndc_z > 1)):
        bits |= out.view(np.uint8) << np.uint8(i)
    bits |= (~(w > 0)).view(np.uint8) << np.uint8(7)
    b0, b1, b2 = (np.take(bits, f, axis=-1) for f in (f0, f1, f2))
    outside = (b0 & b1 & b2 & np.uint8(63)) != 0
    behind = ((b0 | b1 | b2) & np.uint8(128)) != 0
    return (area2 < 0) & ~behind & ~outside


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_compiled_cull_is_the_numpy_cull(dtype):
    # Random triangles over and past a 64 px view, vertices on its edges, behind the eye, beyond near and far,
    # degenerate (collinear, repeated) and not finite.
    rng = np.random.default_rng(7)
    t, v, f = 6, 400, 1500
    xy = rng.uniform(-20, 84, (t, v, 2))
    xy[:, ::17, 0] = rng.choice([0.0, 64.0], (t, len(range(0, v, 17))))
    xy[:, 1::19] = np.round(xy[:, 1::19])  # on a grid: many exactly collinear triples
    xy[:, 5::53] = np.nan
    ndc_z = rng.uniform(-1.3, 1.3, (t, v))
    ndc_z[:, ::23] = rng.choice([-1.0, 1.0], (t, len(range(0, v, 23))))
    w = rng.uniform(-0.2, 2, (t, v))
    faces = rng.integers(0, v, (f, 3))
    faces[::31, 1] = faces[::31, 0]
    xy, ndc_z, w = xy.astype(dtype), ndc_z.astype(dtype), w.astype(dtype)
    got = cull(xy, ndc_z, w, faces, 64, 64)
    want = numpy_cull(xy, ndc_z, w, faces, 64, 64)
    assert got.shape == (t, f) and np.array_equal(got, want)
    assert 0.1 < want.mean() < 0.5  # both outcomes, often
    assert np.array_equal(cull(xy[2], ndc_z[2], w[2], faces, 64, 64), want[2])  # one frame, no frame axis


def numpy_project(cam, points):
    """Camera.project as numpy computed it before its tail was compiled (the reference)."""
    m = cam.projection @ cam.view
    p = np.asarray(points, np.float64)
    clip = p @ m[:3, :3].T + m[:3, 3]
    w = p @ m[3, :3] + m[3, 3]
    safe_w = np.where(np.abs(w) > 1e-12, w, 1e-12)
    ndc = clip / safe_w[..., None]
    xy = np.empty(p.shape[:-1] + (2,), np.float64)
    xy[..., 0] = (ndc[..., 0] + 1) * 0.5 * cam.width
    xy[..., 1] = (1 - ndc[..., 1]) * 0.5 * cam.height
    return xy, ndc[..., 2], w


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_compiled_projection_is_the_numpy_projection(ortho, dtype):
    # Points in front of, on and behind the eye plane (w 0, tiny, negative), far outside the view, not finite;
    # shaped as frames (T, V, 3), one frame (V, 3) and one point (3,).
    rng = np.random.default_rng(11)
    frames = rng.normal(0, 1.5, (5, 300, 3))
    cam = Camera.fit(frames[:, :200], size=97, yaw=20, pitch=-10, ortho=ortho)
    eye = cam.eye_position()
    frames[:, ::29] = eye + rng.normal(0, 1e-13, (5, len(range(0, 300, 29)), 3))  # |w| about 1e-12
    frames[:, 3::31] = eye
    frames[:, 7::37] = 2 * eye
    frames[:, 11::41] *= 1e6
    frames[:, 13::43, 1] = np.nan
    frames = frames.astype(dtype)
    for pts in (frames, frames[2], frames[3, 5]):
        got, want = cam.project(pts), numpy_project(cam, pts)
        for g, e in zip(got, want):
            assert g.shape == e.shape and g.dtype == np.float64
            assert np.array_equal(g, e, equal_nan=True)
    w = numpy_project(cam, frames)[2]
    assert ortho or (w <= 0).any()  # points behind the eye, and in float64 some on its plane (the guarded divide)
    assert ortho or dtype == np.float32 or (np.abs(w) <= 1e-12).any()


def numpy_fit_extent(frames, view, ortho):
    """The extent Camera.fit measured as numpy before it was compiled (the reference): row 0 minima, row 1
    negated maxima of (depth, x, y)."""
    eye = np.asarray(frames, np.float64).reshape(-1, 3) @ view[:3, :3].T + view[:3, 3]
    depth = -eye[:, 2]
    xs, ys = (eye[:, 0], eye[:, 1]) if ortho else (eye[:, 0] / depth, eye[:, 1] / depth)
    both = np.stack([depth, xs, ys])
    return np.stack([both.min(axis=1), -both.max(axis=1)])


@pytest.mark.parametrize("ortho", [False, True])
def test_compiled_fit_extent_is_numpys(ortho):
    from converter.viewport import view_extent

    rng = np.random.default_rng(5)
    pts = rng.normal(0, 2, (4000, 3)).astype(np.float32)
    view = look_at(np.array([3.0, 1.0, 12.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    want = numpy_fit_extent(pts, view, ortho)
    got = view_extent(pts.astype(np.float64) @ view[:3, :3].T, view[:3, 3], ortho)
    assert np.array_equal(np.stack([got[0], -got[1]]), want)
    pts[17, 1] = np.nan  # a NaN propagates as numpy's min and max propagate it
    want = numpy_fit_extent(pts, view, ortho)
    got = view_extent(pts.astype(np.float64) @ view[:3, :3].T, view[:3, 3], ortho)
    assert np.array_equal(np.stack([got[0], -got[1]]), want, equal_nan=True) and np.isnan(want).any()
