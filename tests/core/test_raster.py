"""converter.raster draws the ids GL draws (Mesa's llvmpipe, tests/reference/gl_ids.py is the reference)."""

import numpy as np
import pytest
from reference import gl_ids

from conftest import SAMPLE
from converter import idpass, raster
from converter.camera import Camera, frustum, look_at, orthographic
from converter.encode import parallel
from converter.extract import cull, fit_camera

SIZE = 64


def _ortho() -> Camera:
    """Looking down -z at the square [-1, 1]^2 from z = 5, near 1 and far 10: one pixel is 2/64 world units."""
    view = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    return Camera(view, orthographic(-1, 1, -1, 1, 1.0, 10.0), SIZE, SIZE, True)


def _ours(cam: Camera, verts: np.ndarray, faces: np.ndarray, drawn: np.ndarray | None = None) -> np.ndarray:
    drawn = np.ones(len(faces), bool) if drawn is None else drawn
    v = len(verts)
    fixed, xy, z = np.empty((v, 2), np.int64), np.empty((v, 2)), np.empty(v)
    raster.window_positions(np.asarray(verts), cam.projection @ cam.view, cam.width, cam.height, fixed, xy, z)
    ids, depth = np.empty((cam.height, cam.width), np.uint32), np.empty((cam.height, cam.width))
    raster.draw_ids(fixed, xy, z, np.asarray(faces, np.int64), drawn, ids, depth, raster.ALL_TILES, raster.WHOLE)
    return ids


def _gl(cam: Camera, verts: np.ndarray, faces: np.ndarray, drawn: np.ndarray | None = None) -> np.ndarray:
    with gl_ids.IdRenderer(cam.width, cam.height, np.asarray(faces, np.int32), len(verts)) as r:
        return r.render(gl_ids.clip_coords(cam, verts), None if drawn is None else np.flatnonzero(drawn)).copy()


def _px(x: float, y: float, z: float = 0.0) -> list[float]:
    """World point at pixel (x, y) of the 64 px orthographic view (y down), world depth z (larger is nearer)."""
    return [x / SIZE * 2 - 1, 1 - y / SIZE * 2, z]


def test_ids_are_exact_at_pixel_centres_as_counted_by_hand():
    # The triangle's legs are 58 px and its diagonal passes through pixel corners, so it owns the centres
    # (i + .5, j + .5) with 2 <= i, j and i + j + 1 < 62 (the tie rule drops none): ours and GL's alike.
    cam = _ortho()
    verts = np.array([_px(2, 2), _px(2, 60), _px(60, 2)], np.float32)
    faces = np.array([[0, 1, 2]], np.int32)
    j, i = np.mgrid[0:SIZE, 0:SIZE]
    expect = (i >= 2) & (j >= 2) & (i + j + 1 < 62)
    for ids in (_ours(cam, verts, faces), _gl(cam, verts, faces)):
        assert np.array_equal(ids == 1, expect)
        assert set(np.unique(ids).tolist()) == {0, 1}


def test_the_sample_draws_the_same_ids_as_gl_on_every_pixel():
    from converter.formats import load
    anim = load(SAMPLE)
    cam = fit_camera(anim, 256)
    for k in (0, anim.n_frames // 3, anim.n_frames - 1):
        xy, z, w = cam.project(anim.frames[k])
        drawn = cull(xy, z, w, anim.faces, cam.width, cam.height)
        ours = _ours(cam, anim.frames[k], anim.faces, drawn)
        assert (ours > 0).sum() > 5000  # the face fills a good part of the view
        assert np.array_equal(ours, _gl(cam, anim.frames[k], anim.faces, drawn))


def test_a_soup_of_small_triangles_at_random_depths_draws_as_gl_draws_it():
    # Thousands of 0.1-4 px triangles, either winding (half are back faces), overlapping at random depths, in a
    # perspective view: edges through pixel centres, depth order and culling all decide pixels here.
    rng = np.random.default_rng(11)
    n = 4000
    centre = rng.uniform(-1.1, 1.1, (n, 1, 2))
    corners = centre + rng.uniform(0.002, 0.06, (n, 1, 1)) * rng.normal(0, 1, (n, 3, 2))
    z = rng.uniform(-0.5, 0.5, (n, 1, 1)) + rng.normal(0, 0.05, (n, 3, 1))
    verts = np.concatenate([corners, z], axis=2).reshape(-1, 3).astype(np.float32)
    faces = np.arange(len(verts), dtype=np.int32).reshape(-1, 3)
    view = look_at(np.array([0.0, 0.0, 3.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    cam = Camera(view, frustum(-0.5, 0.5, -0.5, 0.5, 1.0, 6.0), 96, 96, False)
    ours = _ours(cam, verts, faces)
    assert len(np.unique(ours)) > 500
    assert np.array_equal(ours, _gl(cam, verts, faces))


def test_a_pixel_centre_on_a_shared_edge_belongs_to_exactly_one_side_as_in_gl():
    # Squares of two triangles whose diagonal, or whose horizontal or vertical split, runs through pixel centres:
    # every centre inside is drawn once, none left as a hole, and each by the triangle GL picks.
    cam = _ortho()
    verts, faces = [], []
    for (x0, y0), split in (((4.5, 4.5), "diagonal"), ((30.5, 4.5), "horizontal"), ((4.5, 30.5), "vertical")):
        a, b, c, d = _px(x0, y0), _px(x0 + 20, y0), _px(x0 + 20, y0 + 20), _px(x0, y0 + 20)
        i = len(verts)
        if split == "diagonal":  # corners a..d clockwise on screen; each triangle listed counter-clockwise in GL
            verts += [a, b, c, d]
            faces += [[i, i + 2, i + 1], [i, i + 3, i + 2]]
        else:
            m0, m1 = (_px(x0, y0 + 10), _px(x0 + 20, y0 + 10)) if split == "horizontal" else \
                (_px(x0 + 10, y0), _px(x0 + 10, y0 + 20))
            verts += [a, b, c, d, m0, m1]
            faces += ([[i, i + 5, i + 1], [i, i + 4, i + 5], [i + 4, i + 2, i + 5], [i + 4, i + 3, i + 2]]
                      if split == "horizontal" else
                      [[i, i + 5, i + 4], [i, i + 3, i + 5], [i + 4, i + 2, i + 1], [i + 4, i + 5, i + 2]])
    verts = np.array(verts, np.float32)
    faces = np.array(faces, np.int32)
    ours = _ours(cam, verts, faces)
    for (x0, y0), parts in (((4.5, 4.5), 2), ((30.5, 4.5), 4), ((4.5, 30.5), 4)):  # centres in the closed square
        inside = ours[int(y0 + 0.5):int(y0 + 20), int(x0 + 0.5):int(x0 + 20)]
        assert (inside > 0).all()
        assert len(np.unique(inside)) == parts
    assert np.array_equal(ours, _gl(cam, verts, faces))


def test_back_faces_are_culled_and_what_crosses_the_near_or_far_plane_is_clipped_as_in_gl():
    cam = _ortho()  # eye at z = 5, near plane at z = 4, far plane at z = -5
    front = [_px(2, 2, 0.0), _px(2, 30, 0.0), _px(30, 2, 0.0)]
    back = [_px(2, 2, 1.0), _px(30, 2, 1.0), _px(2, 30, 1.0)]  # nearer, but facing away: hides nothing
    tilted_far = [_px(36, 36, -8.3), _px(36, 62, -2.1), _px(62, 36, -2.2)]  # its near part only
    tilted_near = [_px(4, 34, 6.1), _px(4, 62, 2.9), _px(30, 34, 3.3)]  # its far part only
    verts = np.array(front + back + tilted_far + tilted_near, np.float32)
    faces = np.arange(12, dtype=np.int32).reshape(4, 3)
    ours = _ours(cam, verts, faces)
    assert not (ours == 2).any()
    assert (ours == 3).any() and (ours == 4).any()
    assert ours[37, 37] == 0 and ours[35, 5] == 0  # the corners beyond the far and the near plane are clipped off
    assert (ours == 1).sum() > 300
    assert np.array_equal(ours, _gl(cam, verts, faces))


def test_a_corner_beyond_the_fixed_point_range_is_drawn_in_float():
    # A perspective corner almost in the eye plane lands ~1e9 px away; the part in view is still drawn.
    view = look_at(np.array([0.0, 0.0, 3.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    cam = Camera(view, frustum(-0.5, 0.5, -0.5, 0.5, 1.0, 6.0), SIZE, SIZE, False)
    verts = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.3, 0.4, 2.999999]], np.float32)
    faces = np.array([[0, 1, 2]], np.int32)
    fixed, xy, z = np.empty((3, 2), np.int64), np.empty((3, 2)), np.empty(3)
    raster.window_positions(verts, cam.projection @ cam.view, SIZE, SIZE, fixed, xy, z)
    assert fixed[2, 0] == raster.FAR and abs(xy[2]).max() > raster.LIMIT
    ours = _ours(cam, verts, faces)
    assert (ours == 1).sum() > 100
    assert (ours == _gl(cam, verts, faces)).mean() > 0.99  # float edges: no exact tie rule that far out


def test_the_pass_keeps_the_same_triangles_on_one_thread_or_two_and_reports_progress(monkeypatch):
    from converter.formats import load
    anim = load(SAMPLE).sliced(0, 70)
    cam = fit_camera(anim, 128)
    xy, z, w = cam.project(anim.frames)
    visible = cull(xy, z, w, anim.faces, cam.width, cam.height)
    got = []
    for threads, budget in ((1, idpass.SLOT_BUDGET), (2, idpass.SLOT_BUDGET), (2, 1)):  # budget 1: one slot
        monkeypatch.setattr(parallel, "THREADS", threads)
        monkeypatch.setattr(idpass, "SLOT_BUDGET", budget)
        seen: list[float] = []
        got.append(idpass.ever_seen(anim.frames, anim.faces, cam, visible, progress=seen.append))
        slots = threads if budget > 1 else 1
        assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) == -(-70 // (idpass.CHUNK * slots))
    assert np.array_equal(got[0], got[1]) and np.array_equal(got[0], got[2]) and got[0].sum() > 100


@pytest.mark.parametrize("shape", [(0, 5), (3, 0)])
def test_no_frames_or_no_faces_keep_nothing(shape):
    t, f = shape
    cam = _ortho()
    kept = idpass.ever_seen(np.zeros((t, 3, 3), np.float32), np.zeros((f, 3), np.int32), cam, np.zeros((t, f), bool))
    assert kept.shape == (f,) and not kept.any()
