"""The occlusion pass keeps every visible triangle, however small, and drops the ones strictly behind (15.8)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from reference import gl_ids

from conftest import SAMPLE
from converter import idpass
from converter.camera import Camera, frustum, look_at, orthographic
from converter.errors import RenderError
from converter.extract import cull

SIZE = 64


def _camera() -> Camera:
    """Orthographic, looking down -z at the square [-1, 1]^2: one pixel is 2/64 world units, y up."""
    view = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    return Camera(view, orthographic(-1, 1, -1, 1, 1.0, 10.0), SIZE, SIZE, True)


def _px(x: float, y: float, z: float) -> list[float]:
    """World point at pixel (x, y) of the 64 px view (y down), at world depth z (larger is nearer)."""
    return [x / SIZE * 2 - 1, 1 - y / SIZE * 2, z]


def _tri(a, b, c, z: float) -> list[list[float]]:
    """A counter-clockwise (front-facing) triangle from pixel corners listed clockwise on screen (y down)."""
    return [_px(*a, z), _px(*c, z), _px(*b, z)]


def _kept(tris: list[list[list[float]]], frames: int = 1) -> np.ndarray:
    verts = np.array(tris, np.float32).reshape(1, -1, 3).repeat(frames, 0)
    faces = np.arange(verts.shape[1], dtype=np.int32).reshape(-1, 3)
    cam = _camera()
    xy, z, w = cam.project(verts)
    return idpass.ever_seen(verts, faces, cam, cull(xy, z, w, faces, SIZE, SIZE))


BIG = _tri((2, 2), (60, 2), (2, 60), 0.0)  # covers the top-left half of the view, at depth 0


def test_tiny_triangle_in_front_covering_one_pixel_centre_is_kept():
    # 0.3 px across, around the centre of pixel (10, 10), in front of the big one: it owns that one centre.
    tiny = _tri((10.35, 10.35), (10.65, 10.4), (10.4, 10.65), 0.1)
    assert _kept([BIG, tiny]).tolist() == [True, True]


def test_triangle_strictly_behind_is_dropped_and_wins_when_brought_forward():
    inner = _tri((5, 5), (30, 5), (5, 30), -0.2)
    assert _kept([BIG, inner]).tolist() == [True, False]
    front = _tri((5, 5), (30, 5), (5, 30), 0.2)
    assert _kept([BIG, front]).tolist() == [True, True]


def test_sub_pixel_triangle_in_front_is_kept_and_behind_is_dropped():
    # Between pixel centres (no centre inside): only rule 2 can keep it.
    corners = ((10.55, 10.55), (10.95, 10.6), (10.6, 10.95))
    assert _kept([BIG, _tri(*corners, 0.05)]).tolist() == [True, True]
    assert _kept([BIG, _tri(*corners, -0.05)]).tolist() == [True, False]


def test_sub_pixel_strip_at_a_convex_ridge_is_kept():
    # A tent: the left plane rises toward x = 20.6, a 0.3 px strip (no pixel centre: 20.5 < x < 21.5) bends
    # away, the right plane falls. The left plane, extended to the strip's centroid, is nearer than the strip:
    # only the slope tolerance of rule 2 tells "same surface, bent" from "behind".
    def p(x, y, z):
        return _px(x, y, z)
    z0, z1 = 0.206, 0.203
    left = [p(2, 2, 0.02), p(20.6, 40, z0), p(20.6, 2, z0)]
    strip = [[p(20.6, 2, z0), p(20.6, 40, z0), p(20.9, 40, z1)], [p(20.6, 2, z0), p(20.9, 40, z1), p(20.9, 2, z1)]]
    right = [p(20.9, 2, z1), p(20.9, 40, z1), p(40, 40, 0.01)]
    kept = _kept([left, *strip, right])
    assert kept.tolist() == [True, True, True, True]
    sunk = [[[x, y, z - 0.05] for x, y, z in t] for t in strip]  # the same strip 0.05 behind: a crack's floor
    assert _kept([left, *sunk, right]).tolist() == [True, False, False, True]


def test_back_facing_and_off_screen_triangles_hide_nothing_and_are_not_kept():
    back = [BIG[0], BIG[2], BIG[1]]
    back = [[x, y, 0.3] for x, y, _ in back]
    assert _kept([BIG, back]).tolist() == [True, False]
    far_off = _tri((200, 200), (260, 200), (200, 260), 0.5)
    assert _kept([BIG, far_off]).tolist() == [True, False]


def test_a_triangle_the_frame_does_not_draw_hides_nothing():
    # Perspective, eye at z = 5: a big triangle with one corner behind the eye is culled (the SVG never draws it),
    # though GL would draw its part in front of the near plane over the small one, which must stay.
    cam = Camera(look_at(np.array([0.0, 0, 5]), np.zeros(3), np.array([0.0, 1, 0])),
                 frustum(-0.1, 0.1, -0.1, 0.1, 0.2, 20.0), SIZE, SIZE, False)
    small = [[-0.3, -0.3, 0.0], [0.3, -0.3, 0.0], [0.0, 0.3, 0.0]]
    cover = [[-2.0, -2.0, 3.0], [2.0, -2.0, 3.0], [0.0, 3.0, 6.0]]  # the last corner behind the eye
    verts = np.array([small, cover], np.float32).reshape(1, 6, 3)
    faces = np.arange(6, dtype=np.int32).reshape(2, 3)
    xy, z, w = cam.project(verts)
    vis = cull(xy, z, w, faces, SIZE, SIZE)
    assert vis.tolist() == [[True, False]]
    with gl_ids.IdRenderer(SIZE, SIZE, faces, 6) as r:  # drawn whole, GL hides the small one behind the cover
        everything = r.render(gl_ids.clip_coords(cam, verts[0]))
        assert (everything == 2).any() and not (everything == 1).any()
        only_drawn = r.render(gl_ids.clip_coords(cam, verts[0]), np.array([0]))
        assert (only_drawn == 1).any() and set(np.unique(only_drawn)) <= {0, 1}
        assert np.array_equal(r.render(gl_ids.clip_coords(cam, verts[0])), everything)  # all faces again
    assert idpass.ever_seen(verts, faces, cam, vis).tolist() == [True, False]


def test_a_triangle_seen_in_any_frame_is_kept():
    verts = np.array([BIG, _tri((5, 5), (30, 5), (5, 30), -0.2)], np.float32).reshape(1, -1, 3).repeat(3, 0)
    verts[2, 3:, 2] = 0.2  # the small one comes forward in the last frame
    faces = np.arange(6, dtype=np.int32).reshape(-1, 3)
    cam = _camera()
    xy, z, w = cam.project(verts)
    vis = cull(xy, z, w, faces, SIZE, SIZE)
    assert idpass.ever_seen(verts, faces, cam, vis).tolist() == [True, True]
    assert idpass.ever_seen(verts[:2], faces, cam, vis[:2]).tolist() == [True, False]


def test_missing_egl_raises_render_error_naming_what_to_install(monkeypatch):
    import OpenGL.platform

    from converter import egl

    # PyOpenGL without an EGL platform (no libEGL), then an EGL library with no usable display.
    with monkeypatch.context() as m:
        m.setattr(OpenGL.platform.PlatformPlugin, "by_name", classmethod(lambda cls, name: None))
        with pytest.raises(RenderError, match="apt-get install libegl1"):
            gl_ids.IdRenderer(8, 8, np.zeros((1, 3), np.int32), 3)
    with monkeypatch.context() as m:
        m.setattr(egl, "_display", lambda e: None)
        with pytest.raises(RenderError, match="apt-get install libegl1.*no EGL display"):
            gl_ids.IdRenderer(8, 8, np.zeros((1, 3), np.int32), 3)
    with gl_ids.IdRenderer(8, 8, np.zeros((1, 3), np.int32), 3) as r:  # and a working one afterwards
        assert r.render(np.zeros((3, 4), np.float32)).shape == (8, 8)


def test_a_conversion_with_the_occlusion_pass_imports_neither_pyrender_nor_trimesh(tmp_path):
    # pyrender's package (trimesh, its scene graph) cost ~0.5 s CPU and ~80 MB in every conversion when the id pass
    # took its EGL context from it; converter.egl makes the context from PyOpenGL alone.
    code = (
        "import sys; import converter.convert as c; from converter.options import ConversionOptions; "
        "r = c.convert(sys.argv[1], ConversionOptions(size=64, end=3)); "
        "assert r.report.counts['paths'] > 0; "
        "print(sorted(m for m in ('pyrender', 'trimesh') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code, str(SAMPLE)], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[2], check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout


def test_on_the_sample_every_pixel_owner_is_kept_and_fewer_visible_triangles_are_missed_than_before(sample_path):
    # Old = the multisampled pyrender pass this replaced. Every triangle owning a pixel centre (the centre
    # samples of a 5x finer id render) is kept, which the old pass fails (80 of them at 192 px, lost in MSAA
    # blends); of the triangles owning any sample of the 5x render, the new pass misses fewer than the old
    # (about a quarter as many when written: sub-pixel slivers covered at every probe, see converter.idpass).
    from bench.legacy_occlusion import legacy_triangle_ids
    from converter.extract import fit_camera
    from converter.formats import load

    anim = load(sample_path)
    frames = anim.frames[::12]
    cam = fit_camera(anim, 192)
    xy, z, w = cam.project(frames)
    vis = cull(xy, z, w, anim.faces, cam.width, cam.height)
    new = idpass.ever_seen(frames, anim.faces, cam, vis)
    old = (legacy_triangle_ids(frames, anim.faces, cam) & vis).any(0)
    s, f = 5, anim.n_faces
    fine = Camera(cam.view, cam.projection, cam.width * s, cam.height * s, cam.ortho)
    seen_fine, owns_centre = np.zeros(f, bool), np.zeros(f, bool)
    with gl_ids.IdRenderer(fine.width, fine.height, anim.faces, anim.n_vertices) as r:
        for k in range(len(frames)):
            ids = r.render(gl_ids.clip_coords(fine, frames[k]))
            seen_fine |= (np.bincount(ids.ravel(), minlength=f + 1)[1:] > 0) & vis[k]
            owns_centre |= (np.bincount(ids[s // 2::s, s // 2::s].ravel(), minlength=f + 1)[1:] > 0) & vis[k]
    assert not (owns_centre & ~new).any()
    assert (seen_fine & ~new).sum() <= (seen_fine & ~old).sum()


def test_the_id_pass_asks_llvmpipe_for_no_raster_threads_unless_the_environment_chooses(monkeypatch):
    from converter import egl

    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    seen = []
    with egl._raster_threads(0):
        seen.append(os.environ.get("LP_NUM_THREADS"))
    seen.append(os.environ.get("LP_NUM_THREADS"))
    monkeypatch.setenv("LP_NUM_THREADS", "3")
    with egl._raster_threads(0):
        seen.append(os.environ.get("LP_NUM_THREADS"))
    assert seen == ["0", None, "3"]
    # Rasterising on one thread draws the same ids (llvmpipe is deterministic in its thread count).
    cam = Camera(look_at(np.array([0.0, 0, 3]), np.zeros(3), np.array([0.0, 1, 0])),
                 orthographic(-1, 1, -1, 1, 0.1, 10), 64, 64, True)
    rng = np.random.default_rng(2)
    verts = rng.uniform(-1, 1, (60, 3))
    faces = rng.integers(0, 60, (40, 3)).astype(np.int32)
    clip = gl_ids.clip_coords(cam, verts)
    ids = []
    for threads in ("2", "0"):  # the environment's choice wins over the id pass's 0
        monkeypatch.setenv("LP_NUM_THREADS", threads)
        with gl_ids.IdRenderer(64, 64, faces, 60) as r:
            ids.append(r.render(clip).copy())
    assert ids[0].any() and np.array_equal(ids[0], ids[1])


# --- rule 2 as numpy computed it before it was compiled: the compiled loop must keep exactly the same set ---------
def _reference_ever_seen(frames, faces, camera, visible):
    kept = np.zeros(faces.shape[0], bool)
    faces64 = faces.astype(np.int64)
    for k in range(frames.shape[0]):
        clip = gl_ids.clip_coords(camera, frames[k])
        drawn = np.flatnonzero(visible[k])  # only what the SVG draws in the frame can hide: a mesh of just those
        with gl_ids.IdRenderer(camera.width, camera.height, faces[drawn], frames.shape[1]) as r:
            ids = r.render(clip)
        ids = np.where(ids > 0, drawn[ids.astype(np.intp) - 1] + 1, 0)
        shown = np.zeros(faces.shape[0] + 1, bool)
        shown[ids.ravel().astype(np.intp)] = True
        kept |= shown[1:] & visible[k]
        cand = np.flatnonzero(visible[k] & ~kept)
        if cand.size:
            w = clip[:, 3].astype(np.float64)
            xy = np.empty((clip.shape[0], 2))
            xy[:, 0] = (clip[:, 0] / w + 1) * 0.5 * camera.width
            xy[:, 1] = (1 - clip[:, 1] / w) * 0.5 * camera.height
            cand = cand[_inradius(xy, faces64[cand]) < idpass.INRADIUS_PX]
            kept[cand] = _subpixel_kept(ids, xy, clip[:, 2] / w, faces64, cand)
    return kept


def _inradius(xy, tri):
    p = xy[tri]
    a, b, c = (np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in ((1, 2), (2, 0), (0, 1)))
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) / np.maximum(a + b + c, 1e-12)


def _subpixel_kept(ids, xy, z, faces, cand):
    tri = faces[cand]
    p = xy[tri]
    cen = p.mean(axis=1)
    z0_t, p0_t, g_t = _plane(p, z[tri])
    kept = np.zeros(len(cand), bool)
    for probe in (cen, *(idpass.PROBE_IN * cen + (1 - idpass.PROBE_IN) * p[:, i] for i in range(3))):
        h, w = ids.shape
        col = np.clip(np.floor(probe[:, 0]).astype(np.int64), 0, w - 1)
        row = np.clip(np.floor(probe[:, 1]).astype(np.int64), 0, h - 1)
        owner = ids[row, col].astype(np.int64) - 1
        empty = owner < 0
        otri = faces[np.where(empty, 0, owner)]
        z0_o, p0_o, g_o = _plane(xy[otri], z[otri])
        z_t = z0_t + ((probe - p0_t) * g_t).sum(axis=1)
        z_o = z0_o + ((probe - p0_o) * g_o).sum(axis=1)
        reach = np.hypot(probe[:, 0] - col - 0.5, probe[:, 1] - row - 0.5)
        tol = idpass.SLACK * np.linalg.norm(g_t - g_o, axis=1) * reach + idpass.DEPTH_EPS
        kept |= empty | (z_t <= z_o + tol)
    return kept


def _plane(p, z):
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = z[:, 1] - z[:, 0], z[:, 2] - z[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    safe = np.where(np.abs(det) > 1e-12, det, np.inf)
    return z[:, 0], p[:, 0], np.column_stack([(d1 * e2[:, 1] - d2 * e1[:, 1]) / safe,
                                              (d2 * e1[:, 0] - d1 * e2[:, 0]) / safe])


def test_compiled_sub_pixel_rule_keeps_what_numpy_kept():
    # A soup of tiny triangles (many below a pixel) at random depths over a big one, moving over 12 frames: rule 2
    # decides hundreds of them both ways, and the compiled loop must decide each as numpy did.
    rng = np.random.default_rng(5)
    n = 1500
    centre = rng.uniform(4, 60, (n, 1, 2))
    size = rng.uniform(0.05, 1.6, (n, 1, 1))
    corners = centre + size * rng.normal(0, 1, (n, 3, 2))
    depth = rng.uniform(-0.05, 0.05, (n, 1, 1)).repeat(3, 1)
    soup = np.concatenate([corners, depth], axis=2)
    drift = np.linspace(0, 3, 12)[:, None, None, None] * np.array([0.2, 0.1, 0.0])
    soup = soup[None] + drift  # (T, n, 3, 3) pixel x, y and depth
    big = np.array(BIG, np.float64)[None, None].repeat(12, 0)
    world = np.stack([soup[..., 0] / SIZE * 2 - 1, 1 - soup[..., 1] / SIZE * 2, soup[..., 2]], axis=-1)
    world = np.concatenate([big, world[..., ::-1, :]], axis=1)  # corners reversed as _tri does (random: half face away)
    verts = world.reshape(12, -1, 3).astype(np.float32)
    faces = np.arange(verts.shape[1], dtype=np.int32).reshape(-1, 3)
    cam = _camera()
    xy, z, w = cam.project(verts)
    visible = cull(xy, z, w, faces, SIZE, SIZE)
    got = idpass.ever_seen(verts, faces, cam, visible)
    want = _reference_ever_seen(verts, faces, cam, visible)
    assert np.array_equal(got, want)
    # Rule 2 had work on both sides: triangles kept only by it, and sub-pixel ones it dropped.
    centres = np.zeros(faces.shape[0], bool)
    with gl_ids.IdRenderer(SIZE, SIZE, faces, verts.shape[1]) as r:
        for k in range(12):
            ids = np.unique(r.render(gl_ids.clip_coords(cam, verts[k])))
            centres[ids[ids > 0] - 1] = True
    assert (want & ~centres).sum() > 20 and (visible.any(axis=0) & ~want).sum() > 20


def test_compiled_sub_pixel_rule_keeps_what_numpy_kept_on_the_sample():
    from converter.extract import fit_camera
    from converter.formats import load
    anim = load(SAMPLE).sliced(0, 40)
    cam = fit_camera(anim)
    xy, z, w = cam.project(anim.frames)
    visible = cull(xy, z, w, anim.faces, cam.width, cam.height)
    got = idpass.ever_seen(anim.frames, anim.faces, cam, visible)
    assert np.array_equal(got, _reference_ever_seen(anim.frames, anim.faces, cam, visible))


# --- a frame is drawn only in the tiles around the triangles it may still add ------------------------------------
def test_candidate_tiles_are_those_near_the_visible_triangles_not_yet_kept():
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]], np.int64)
    xy = np.array([[20.5, 3.0], [22.0, 3.5], [21.0, 5.0],  # pixels 20..22 x 3..5: with the margin 18..24 x 1..7
                   [40.0, 40.0], [41.0, 40.0], [40.0, 41.0],  # kept already
                   [60.0, 60.0], [61.0, 60.0], [60.0, 61.0]])  # not drawn in this frame
    fixed = np.rint(xy * 256).astype(np.int64)
    visible, kept = np.array([True, True, False]), np.array([False, True, False])
    tiles = np.zeros((8, 8), bool)  # 8 px tiles of a 64 px frame
    assert idpass.candidate_tiles(xy, fixed, faces, visible, kept, tiles, 8)
    want = np.zeros((8, 8), bool)
    want[0, 2:4] = True  # rows 1..7 are tile row 0; columns 18..24 are tile columns 2 and 3
    assert np.array_equal(tiles, want)

    kept[0] = True  # nothing left to find: no tile, and the frame is not drawn
    assert not idpass.candidate_tiles(xy, fixed, faces, visible, kept, tiles, 8) and not tiles.any()

    kept[0] = False  # a corner off the frame is clamped into it, as rule 2 clamps a probe's pixel
    xy[:3] += [-30.0, 70.0]
    fixed = np.rint(xy * 256).astype(np.int64)
    assert idpass.candidate_tiles(xy, fixed, faces, visible, kept, tiles, 8)
    assert np.flatnonzero(tiles.ravel()).tolist() == [56]  # the bottom-left tile only

    xy[1, 0] = np.nan  # a corner not finite: every tile
    assert idpass.candidate_tiles(xy, fixed, faces, visible, kept, tiles, 8) and tiles.all()


@pytest.mark.parametrize("tile", [1, 4, 16])
def test_drawing_only_the_candidates_tiles_keeps_what_whole_frames_keep(monkeypatch, tile):
    # The soup of tiny triangles over a big one, and the sample, over several frames: as triangles get kept, each
    # frame is drawn in fewer tiles, and the kept set must be that of drawing every frame whole (one tile).
    rng = np.random.default_rng(11)
    n = 600
    corners = rng.uniform(4, 60, (n, 1, 2)) + rng.uniform(0.05, 3.0, (n, 1, 1)) * rng.normal(0, 1, (n, 3, 2))
    depth = rng.uniform(-0.05, 0.05, (n, 1, 1)).repeat(3, 1)
    soup = np.concatenate([corners, depth], axis=2)[None] + np.linspace(0, 4, 10)[:, None, None, None] * [0.3, 0.2, 0]
    world = np.stack([soup[..., 0] / SIZE * 2 - 1, 1 - soup[..., 1] / SIZE * 2, soup[..., 2]], axis=-1)
    world = np.concatenate([np.array(BIG, np.float64)[None, None].repeat(10, 0), world], axis=1)
    verts = world.reshape(10, -1, 3).astype(np.float32)
    faces = np.arange(verts.shape[1], dtype=np.int32).reshape(-1, 3)
    cam = _camera()
    xy, z, w = cam.project(verts)
    cases = [(verts, faces, cam, cull(xy, z, w, faces, SIZE, SIZE))]
    from converter.extract import fit_camera
    from converter.formats import load
    anim = load(SAMPLE).sliced(0, 30)
    cam = fit_camera(anim, 128)
    xy, z, w = cam.project(anim.frames)
    cases.append((anim.frames, anim.faces, cam, cull(xy, z, w, anim.faces, cam.width, cam.height)))
    from converter import raster
    for frames, faces, cam, visible in cases:
        monkeypatch.setattr(idpass, "TILE", raster.WHOLE)
        whole = idpass.ever_seen(frames, faces, cam, visible)
        monkeypatch.setattr(idpass, "TILE", tile)
        tiled = idpass.ever_seen(frames, faces, cam, visible)
        assert np.array_equal(tiled, whole)
        assert 0 < whole.sum() < visible.any(axis=0).sum()  # some front-facing triangles stay hidden throughout
