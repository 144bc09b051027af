"""The puppet's triangle budget (converter/puppet/budget.py): fewer triangles, the same face on screen.

The budgeted mesh is drawn against the full one by the CPU id raster (converter.raster, GL's rules) in poses the
budget sampled and in poses it did not (another seed's random combinations): silhouettes and each part's pixels
agree, and the triangles the occlusion step dropped own no pixel in any of them.
"""

from __future__ import annotations

import numpy as np
import pytest

from converter import raster
from converter.extract import cull
from converter.puppet import budget, build

POSES_IOU = 0.99  # silhouette IoU of the budgeted mesh against the full one, every pose
DROPPED_PX = 2  # pixels the occlusion step's dropped triangles may own in a pose it did not sample (sub-pixel luck)


def ids_image(points: np.ndarray, faces: np.ndarray, camera) -> np.ndarray:
    """(H, W) int64 triangle index + 1 each pixel shows (0: background), front faces in view, nearest wins."""
    v, h, w = len(points), camera.height, camera.width
    fixed, xy, z = np.empty((v, 2), np.int64), np.empty((v, 2)), np.empty(v)
    m = np.ascontiguousarray(camera.projection @ camera.view, np.float64)
    raster.window_positions(np.ascontiguousarray(points, np.float32), m, w, h, fixed, xy, z)
    pxy, pz, pw = camera.project(np.asarray(points, np.float32)[None])
    faces = np.ascontiguousarray(faces, np.int64)
    drawn = np.ascontiguousarray(cull(pxy, pz, pw, faces, w, h)[0], np.bool_)
    ids, depth = np.empty((h, w), np.uint32), np.empty((h, w))
    raster.draw_ids(fixed, xy, z, faces, drawn, ids, depth, raster.ALL_TILES, raster.WHOLE)
    return ids.astype(np.int64)


def test_pose_samples_cover_targets_turns_and_combinations(face):
    pivot = 0.5 * (face.base.min(0) + face.base.max(0))
    blocks = list(budget.poses(face, pivot))
    n = sum(len(b) for b in blocks)
    eyes = 2 * len(budget.EYE_GRID) ** 2
    assert n == (1 + len(face.names) * len(budget.MORPH_WEIGHTS) + len(budget.HEAD_GRID) ** 2 + eyes
                 + len(budget.WIDEST_GRID) ** 2 + budget.SEEDED_POSES)
    again = list(budget.poses(face, pivot))  # a fixed seed: the same puppet every build
    assert all(np.array_equal(a, b) for a, b in zip(blocks, again))


SMALL_BUDGET = 1200  # the generated face shows ~1,900 triangles, under budget.MAX_TRIANGLES: simplified towards this
SMALL_BOUND_PX = 1.5  # ... within this (its coarse sphere keeps every vertex within budget.BOUND_PX)


@pytest.fixture(scope="module")
def meshes(face, puppet):
    """(full puppet, budgeted puppet simplified towards SMALL_BUDGET within SMALL_BOUND_PX) of the generated face,
    the same camera."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(budget, "MAX_TRIANGLES", SMALL_BUDGET)
        mp.setattr(budget, "BOUND_PX", SMALL_BOUND_PX)
        return build(face, puppet.camera, budget=False), build(face, puppet.camera)


def test_the_budget_keeps_fewer_triangles_on_fewer_vertices(meshes):
    full, cut = meshes
    assert len(cut.triangles) < 0.8 * len(full.triangles)
    assert len(cut.xy) < len(full.xy)
    assert cut.info["facing_triangles"] == len(full.triangles)
    assert cut.info["occluded_triangles"] > 0  # the eyeballs' backs behind the head's surface
    # the simplified mesh lies on the face's own vertices: its positions are the full puppet's
    at = {int(v): i for i, v in enumerate(full.source_vertices)}
    same = np.array([at[int(v)] for v in cut.source_vertices])
    assert np.array_equal(cut.xy, full.xy[same])


def posed(face, pivot, rng: np.random.Generator) -> np.ndarray:
    """A random pose the budget did not sample: targets set at random, head and an eye turned."""
    w = rng.uniform(0, 1, len(face.names)) * (rng.uniform(0, 1, len(face.names)) < 0.5)
    pts = face.base + np.tensordot(w.astype(np.float32), face.deltas, axes=1)
    head = [rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(-15, 15)]
    return budget.turned(pts, pivot, np.array([head]))[0]


def test_the_budgeted_mesh_draws_the_full_meshs_face(face, meshes):
    """Silhouette IoU >= POSES_IOU and each part's pixels within 3%, in sampled and unsampled poses."""
    full, cut = meshes
    cam = full.camera
    full_faces = full.source_vertices[full.triangles]
    cut_faces = cut.source_vertices[cut.triangles]
    pivot = full.pivot.astype(np.float32)
    rng = np.random.default_rng(7)
    poses = [face.base, face.base + face.deltas[face.names.index("jawOpen")],
             budget.turned(face.base, pivot, np.array([[20.0, -15.0, 0.0]]))[0]]
    poses += [posed(face, pivot, rng) for _ in range(6)]
    full_parts = np.r_[-1, face.part_ids[[_source_face(face, t) for t in full_faces]]]
    for k, pts in enumerate(poses):
        a, b = ids_image(pts, full_faces, cam), ids_image(pts, cut_faces, cam)
        iou = ((a > 0) & (b > 0)).sum() / max(((a > 0) | (b > 0)).sum(), 1)
        assert iou >= POSES_IOU, (k, iou)
        cut_parts = np.r_[-1, _parts_of(face, cut)]
        pa, pb = full_parts[a], cut_parts[b]
        for p in np.unique(pa[pa >= 0]):
            assert abs(int((pb == p).sum()) - int((pa == p).sum())) <= max(0.03 * (pa == p).sum(), 4), (k, p)


def _source_face(face, corners: np.ndarray) -> int:
    """The face's triangle with these vertex ids (any order)."""
    return int(np.flatnonzero((np.sort(face.faces, 1) == np.sort(corners)).all(1))[0])


def _parts_of(face, puppet) -> np.ndarray:
    """The part of each puppet triangle: the part of the face's triangles its first corner's vertex belongs to."""
    part_of_vertex = np.zeros(len(face.base), np.int64)
    part_of_vertex[face.faces.ravel()] = np.repeat(face.part_ids, 3)
    corners = puppet.source_vertices[puppet.triangles]
    # a corner shared by two parts is ambiguous; the triangle's part is the one most of its corners belong to
    votes = part_of_vertex[corners]
    return np.array([np.bincount(v).argmax() for v in votes])


def test_dropped_triangles_own_no_pixel_in_any_pose(face, puppet):
    """The occlusion step's dropped triangles, drawn with the whole face, own no pixel in the sampled poses and at
    most DROPPED_PX in poses it did not sample."""
    cam = puppet.camera
    pivot = 0.5 * (face.base.min(0) + face.base.max(0))
    faces = face.faces.astype(np.int64)
    xy, z, w = cam.project(face.base.astype(np.float32)[None])
    facing = np.ones(len(faces), bool)
    kept = budget.seen(face, cam, pivot.astype(np.float32), facing)
    dropped = np.flatnonzero(~kept)
    assert len(dropped) > 0
    sampled = np.concatenate(list(budget.poses(face, pivot.astype(np.float32))))
    for pts in sampled[:: max(1, len(sampled) // 40)]:
        ids = ids_image(pts, faces, cam)
        assert not np.isin(ids - 1, dropped).any()
    rng = np.random.default_rng(11)
    for _ in range(8):
        ids = ids_image(posed(face, pivot.astype(np.float32), rng), faces, cam)
        assert np.isin(ids - 1, dropped).sum() <= DROPPED_PX


def test_no_budget_keeps_every_shown_triangle(face, meshes):
    full, _ = meshes
    assert full.info["occluded_triangles"] == 0 and full.info["budget_px"] == 0.0


def test_a_mesh_within_the_budget_is_not_simplified(face, puppet):
    """Under budget.MAX_TRIANGLES only the occlusion step drops triangles: the rest are the face's own."""
    cut = build(face, puppet.camera)
    assert len(cut.triangles) == cut.info["facing_triangles"] - cut.info["occluded_triangles"]
    faces = {tuple(sorted(t)) for t in face.faces.tolist()}
    assert all(tuple(sorted(t)) in faces for t in cut.source_vertices[cut.triangles].tolist())
