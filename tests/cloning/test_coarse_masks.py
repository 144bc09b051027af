"""Automatic landmarks on coarse face masks (a few hundred vertices, front half only, open at the back, in mm, cm
or m, like a 3D morphable model's reference face), and cloning onto one.

The masks are made from the bundled sample face (and, with the shared data, the ICT head's front): its front
half, either decimated by meshoptimizer (irregular triangles, the lips' slit kept) or resampled on a regular grid
of points on the surface as the front sees it (a closed height field: lips joined, eyes covered). Their landmarks
are compared with the ones the rules find on the dense face they came from.
"""

from __future__ import annotations

import json

import meshoptimizer
import numpy as np
import pytest
from scipy.interpolate import griddata

from converter import formats
from converter.animation import FaceAnimation, Part
from converter.cloning import clone, dense, landmarks, local_frames
from converter.errors import InputError
from converter.formats.ictfacekit import load_ict_head

UNITS = {"mm": 10.0, "cm": 1.0, "m": 0.01}  # the sample face is in centimetres
OFFSET = np.array([3.0, -20.0, 5.0])  # cm: a mask need not sit at the origin
# The profile down the middle, top to bottom: each landmark lies below the one before it.
PROFILE = ("nose_top", "nose_tip", "nose_bottom", "lip_top", "mouth", "lip_bottom", "chin")
SKIN = (0.8, 0.6, 0.5)


def compact(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the vertices the faces use, renumbered."""
    used = np.unique(faces)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces].astype(np.int32)


def front_half(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles in front of the plane halfway through the face's depth (an open mask, no back or ears)."""
    mid = 0.5 * (verts[np.unique(faces), 2].min() + verts[np.unique(faces), 2].max())
    return compact(verts, faces[(verts[faces][:, :, 2] > mid).all(1)])


def decimated(verts: np.ndarray, faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """meshoptimizer's simplification down to about n_vertices (collapsed edges: irregular triangles)."""
    goal = int(len(faces) * n_vertices / len(np.unique(faces))) * 3
    dest = np.zeros(faces.size, np.uint32)
    n = meshoptimizer.simplify(dest, faces.astype(np.uint32).ravel(), verts.astype(np.float32),
                               target_index_count=goal, target_error=0.5)
    return compact(verts, dest[:n].reshape(-1, 3).astype(np.int64))


def front_z(verts: np.ndarray, faces: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """The surface's z seen from the front above each point xy (n, 2): the largest z of the triangles whose xy
    projection holds the point (barycentric coordinates), nan where none does."""
    t = verts[faces]  # (F, 3, 3)
    e1, e2 = t[:, 1, :2] - t[:, 0, :2], t[:, 2, :2] - t[:, 0, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-12 * np.ptp(verts[:, :2]) ** 2
    t, e1, e2, det = t[ok], e1[ok], e2[ok], det[ok]
    out = np.full(len(xy), np.nan)
    for s in range(0, len(xy), 64):  # in blocks: (points, triangles, 2) arrays of a few MB
        w = xy[s:s + 64, None, :] - t[None, :, 0, :2]
        u = (w[..., 0] * e2[:, 1] - w[..., 1] * e2[:, 0]) / det
        v = (e1[:, 0] * w[..., 1] - e1[:, 1] * w[..., 0]) / det
        inside = (u >= 0) & (v >= 0) & (u + v <= 1)
        z = np.where(inside, t[:, 0, 2] + u * (t[:, 1, 2] - t[:, 0, 2]) + v * (t[:, 2, 2] - t[:, 0, 2]), -np.inf)
        out[s:s + 64] = z.max(1)
    return np.where(np.isfinite(out), out, np.nan)


def resampled(verts: np.ndarray, faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular grid of about n_vertices points on the surface as the front sees it, two triangles a cell: the
    mouth and eyes closed over, as on a morphable model's mask."""
    tri = verts[faces][:, :, :2]
    d1, d2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]).sum()  # seen from the front
    step = np.sqrt(area / n_vertices)
    lo, hi = verts[:, :2].min(0), verts[:, :2].max(0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + step, step), np.arange(lo[1], hi[1] + step, step))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    z = front_z(verts, faces, xy)
    # Close the holes inside the outline (the eye openings), as a morphable model's mask is closed there: a
    # sample missing with hits on both sides of it along its row and its column takes the surface across them.
    hit = np.isfinite(z).reshape(gx.shape)
    inside = (np.maximum.accumulate(hit, 1) & np.maximum.accumulate(hit[:, ::-1], 1)[:, ::-1]
              & np.maximum.accumulate(hit, 0) & np.maximum.accumulate(hit[::-1], 0)[::-1]).ravel()
    hole = inside & ~np.isfinite(z)
    z[hole] = griddata(xy[~hole & np.isfinite(z)], z[~hole & np.isfinite(z)], xy[hole], method="linear")
    idx = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    grid = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    grid = grid[np.isfinite(z[grid]).all(1)]
    return compact(np.column_stack([xy, z]), grid)


@pytest.fixture(scope="module")
def sample(sample_path):
    """The sample face: its animation, skin, the landmarks on its whole skin and its size (nose top to chin)."""
    anim = formats.load(sample_path)
    verts, faces = anim.frames[0].astype(np.float64), dense.skin_faces(anim)
    pts = landmarks.detect(verts, faces, "sample")
    return dict(anim=anim, verts=verts, faces=faces, pts=pts,
                size=float(np.linalg.norm(pts["nose_top"] - pts["chin"])))


def mask(sample, kind: str, n_vertices: int, unit: str = "cm") -> tuple[np.ndarray, np.ndarray]:
    """A coarse mask of the sample face in the given unit, moved off the origin."""
    v, f = front_half(sample["verts"], sample["faces"])
    v, f = decimated(v, f, n_vertices) if kind == "decimated" else resampled(v, f, n_vertices)
    return (v + OFFSET) * UNITS[unit], f


def in_cm(pts: dict[str, np.ndarray], unit: str) -> dict[str, np.ndarray]:
    return {k: p / UNITS[unit] - OFFSET for k, p in pts.items()}


CASES = [(kind, n, unit) for kind, n in (("decimated", 300), ("decimated", 500), ("resampled", 300),
                                         ("resampled", 500), ("resampled", 900)) for unit in UNITS]


@pytest.mark.parametrize("kind, n_vertices, unit", CASES)
def test_coarse_mask_landmarks_land_on_the_dense_faces(sample, kind, n_vertices, unit):
    v, f = mask(sample, kind, n_vertices, unit)
    assert 0.7 * n_vertices < len(v) < 1.3 * n_vertices
    pts = in_cm(landmarks.detect(v, f, f"{kind}_{n_vertices}_{unit}"), unit)
    # A coarse mask places a point to within its vertex spacing (the median edge: 0.11 face sizes at 300
    # vertices, 0.07 at 900), on average to half of it.
    check_landmarks(pts, sample["pts"], sample["size"], median_edge(v, f) / UNITS[unit])


def check_landmarks(pts: dict[str, np.ndarray], ref: dict[str, np.ndarray], size: float, edge: float) -> None:
    """Every named landmark of ref found within the mask's vertex spacing (its median edge, at least 0.06 face
    sizes) and on average within half of it; the profile's points in order down the face."""
    tol = max(0.06, edge / size)
    named = [k for k in ref if not k.startswith("grid_") and k not in landmarks.EXTENT_POINTS]
    assert set(named) - set(pts) <= {"lip_chin_fold", "glabella"}, set(named) - set(pts)
    errors = {k: float(np.linalg.norm(pts[k] - ref[k]) / size) for k in named if k in pts}
    assert max(errors.values()) < tol, {k: round(e, 3) for k, e in errors.items() if e >= tol}
    assert np.mean(list(errors.values())) < 0.5 * tol, errors
    heights = [pts[k][1] for k in PROFILE]
    assert all(a > b for a, b in zip(heights, heights[1:])), dict(zip(PROFILE, heights))


def median_edge(verts: np.ndarray, faces: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(verts[faces] - verts[np.roll(faces, 1, axis=1)], axis=-1)))


@pytest.fixture(scope="module")
def ict_front(shared_data):
    """The ICT head's front (skin only, with its neck) and the landmarks of its dense faces."""
    h = load_ict_head(str(shared_data / "ict_facekit"))
    names = np.array([p.name for p in h.parts])[h.part_ids]
    v, f = front_half(h.vertices.astype(np.float64), h.faces[names == "skin"])
    # Resampling closes the eye openings, which moves the sockets' floor by 0.07-0.09 face sizes at any density:
    # the dense face of a resampled mask is the same surface resampled finely.
    refs = {"decimated": landmarks.detect(v, f, "ict_mask"),
            "resampled": landmarks.detect(*resampled(v, f, 4000), "ict_mask_resampled")}
    return v, f, refs


@pytest.mark.parametrize("kind, n_vertices", [("decimated", 300), ("decimated", 900), ("resampled", 300),
                                              ("resampled", 900)])
def test_ict_coarse_masks(ict_front, kind, n_vertices):
    """A coarse mask of the ICT head's front in mm against its dense face's landmarks."""
    v, f, refs = ict_front
    ref = refs[kind]
    cv, cf = decimated(v, f, n_vertices) if kind == "decimated" else resampled(v, f, n_vertices)
    pts = landmarks.detect(cv * UNITS["mm"], cf, f"ict_{kind}_{n_vertices}")
    size = float(np.linalg.norm(ref["nose_top"] - ref["chin"]))
    check_landmarks({k: p / UNITS["mm"] for k, p in pts.items()}, ref, size, median_edge(cv, cf))


@pytest.mark.parametrize("kind", ["decimated", "resampled"])
def test_coarse_mask_landmarks_do_not_depend_on_the_unit(sample, kind):
    base = in_cm(landmarks.detect(*mask(sample, kind, 400, "cm")), "cm")
    for unit in ("mm", "m"):
        pts = in_cm(landmarks.detect(*mask(sample, kind, 400, unit)), unit)
        assert pts.keys() == base.keys()
        for k, p in base.items():
            assert np.linalg.norm(pts[k] - p) < 1e-3 * sample["size"], (unit, k)


def chinless(sample, how: str) -> tuple[np.ndarray, np.ndarray]:
    """A coarse millimetre mask without a chin: "cut" below the lower lip (the mesh ends there) or "flattened" (the
    face below the nose pressed onto the plane through the nose's bottom)."""
    v, f = mask(sample, "resampled", 500, "mm")
    nose = (sample["pts"]["nose_bottom"] + OFFSET) * UNITS["mm"]
    chin = (sample["pts"]["chin"] + OFFSET) * UNITS["mm"]
    lip = (sample["pts"]["lip_bottom"] + OFFSET) * UNITS["mm"]
    if how == "cut":  # a third of the way from the lower lip to the chin
        return compact(v, f[(v[f][:, :, 1] > (2 * lip[1] + chin[1]) / 3).all(1)])
    v = v.copy()
    v[v[:, 1] < nose[1], 2] = nose[2]
    return v, f


@pytest.mark.parametrize("how, why", [("cut", r"the mesh ends 0\.\d+ nose lengths below the nose's bottom"),
                                      ("flattened", "flat below the nose")], ids=["cut", "flattened"])
def test_mask_without_a_chin_says_which_landmark_to_give(sample, how, why):
    v, f = chinless(sample, how)
    with pytest.raises(InputError, match=rf"'{how}_mask'.*no chin: .*{why}.*--correspondences with a pair for the "
                                         r"chin and more .*\{\"pairs\": \[\[source, target\]"):
        landmarks.detect(v, f, f"{how}_mask")
    target = FaceAnimation(v[None].astype(np.float32), f, np.zeros(len(f), np.int32), (Part("skin", SKIN),), 30.0,
                           f"{how}_mask")
    with pytest.raises(InputError, match=rf"'{how}_mask'.*no chin"):
        clone(sample["anim"].sliced(0, 3), target, "dense")


def test_correspondences_stand_in_for_a_missing_chin(sample, tmp_path):
    """The advice works: with pairs for the chin and points off the middle, the flattened mask clones."""
    v, f = chinless(sample, "flattened")
    target = FaceAnimation(v[None].astype(np.float32), f, np.zeros(len(f), np.int32), (Part("skin", SKIN),), 30.0,
                           "flattened_mask")
    src = sample["anim"].sliced(0, 70)  # the mouth opens from frame 50 on
    names = ("chin", "mouth_side_left", "mouth_side_right", "eye_socket_left", "eye_socket_right")
    skin = np.unique(sample["faces"])
    on_mask = {}  # where the sample's landmarks are on the mask: the nearest vertex seen from the front
    for name in (*names, "nose_bottom"):
        t = (sample["pts"][name] + OFFSET) * UNITS["mm"]
        on_mask[name] = v[np.argmin(np.linalg.norm(v[:, :2] - t[:2], axis=1))]
    pairs = []
    for name in names:
        s_id = int(skin[np.argmin(np.linalg.norm(sample["verts"][skin] - sample["pts"][name], axis=1))])
        pairs.append([s_id, on_mask[name].tolist()])
    corr = tmp_path / "pairs.json"
    corr.write_text(json.dumps({"pairs": pairs}))
    out = clone(src, target, "dense", correspondences=str(corr))
    assert out.frames.shape == (src.n_frames, target.n_vertices, 3)
    assert np.isfinite(out.frames).all()
    np.testing.assert_allclose(out.frames[0], target.frames[0], atol=1e-2)
    size = np.linalg.norm(on_mask["chin"] - (sample["pts"]["nose_top"] + OFFSET) * UNITS["mm"])
    src_drop = jaw_drop(src.frames, sample["pts"], skin) / sample["size"]
    out_drop = jaw_drop(out.frames, on_mask, np.arange(len(v))) / size
    assert np.corrcoef(src_drop, out_drop)[0, 1] > 0.9
    assert 0.5 < out_drop.max() / src_drop.max() < 2.0, (out_drop.max(), src_drop.max())


def jaw_drop(frames: np.ndarray, pts: dict[str, np.ndarray], ids: np.ndarray) -> np.ndarray:
    """Per frame, how much farther the chin is below the nose's bottom than in frame 0 (the vertices of ids
    nearest the two landmarks)."""
    base = frames[0, ids]
    nose = ids[np.argmin(np.linalg.norm(base - pts["nose_bottom"], axis=1))]
    chin = ids[np.argmin(np.linalg.norm(base - pts["chin"], axis=1))]
    gap = frames[:, nose, 1] - frames[:, chin, 1]
    return gap - gap[0]


def test_sample_animation_cloned_onto_a_coarse_mm_mask_with_automatic_landmarks(sample):
    v, f = mask(sample, "resampled", 600, "mm")
    target = FaceAnimation(v[None].astype(np.float32), f, np.zeros(len(f), np.int32), (Part("skin", SKIN),), 30.0,
                           "coarse_mm")
    src = sample["anim"]
    out = clone(src, target, "dense")
    assert out.frames.shape == (src.n_frames, target.n_vertices, 3)
    assert np.isfinite(out.frames).all()
    np.testing.assert_allclose(out.frames[0], target.frames[0], atol=1e-2)
    # The mask's jaw opens when and as far as the source's does (in face sizes: mm against the sample's cm).
    pts = landmarks.detect(v, f, "coarse_mm")
    size = np.linalg.norm(pts["nose_top"] - pts["chin"])
    src_drop = jaw_drop(src.frames, sample["pts"], np.unique(sample["faces"])) / sample["size"]
    out_drop = jaw_drop(out.frames, pts, np.arange(len(v))) / size
    assert src_drop.max() > 0.1  # the sample opens its mouth
    assert np.corrcoef(src_drop, out_drop)[0, 1] > 0.9
    assert 0.6 < out_drop.max() / src_drop.max() < 1.6, (out_drop.max(), src_drop.max())
    # The chin's region moves as much as the sample's, and the forehead keeps its share of the motion (the
    # sample raises its brows: a third of its chin's motion).
    s_chin, s_brow = regions(src.frames, sample["pts"], np.unique(sample["faces"]), sample["size"])
    o_chin, o_brow = regions(out.frames, pts, np.arange(len(v)), size)
    assert s_chin / 1.5 < o_chin < 1.5 * s_chin, (o_chin, s_chin)
    assert 0.5 < (o_brow / o_chin) / (s_brow / s_chin) < 2.0, (o_brow, o_chin, s_brow, s_chin)


def regions(frames: np.ndarray, pts: dict[str, np.ndarray], ids: np.ndarray, size: float) -> tuple[float, float]:
    """Peak motion in face sizes, averaged over the vertices of ids near the chin and over those of the forehead."""
    base = frames[0, ids]
    motion = np.linalg.norm(frames[:, ids] - base, axis=-1).max(0) / size
    chin = np.linalg.norm(base - pts["chin"], axis=1) < 0.15 * size
    forehead = base[:, 1] > pts["glabella"][1]
    return float(motion[chin].mean()), float(motion[forehead].mean())


def test_frames_method_names_its_own_landmark_file_and_takes_it(sample, tmp_path):
    """The frames method finds landmarks on the source: a chinless one is told to name them, and named ones fill in."""
    v, f = chinless(sample, "flattened")
    with pytest.raises(InputError, match=r"no chin.*\{\"landmarks\": \{name: vertex id\}\}.*dense method"):
        local_frames.landmark_ids(v, f, None, "flattened_mask")
    chin = (sample["pts"]["chin"] + OFFSET) * UNITS["mm"]
    corr = tmp_path / "landmarks.json"
    corr.write_text(json.dumps({"landmarks": {"chin": int(np.argmin(np.linalg.norm(v[:, :2] - chin[:2], axis=1)))}}))
    ids = local_frames.landmark_ids(v, f, str(corr), "flattened_mask")
    assert ids["chin"] == json.loads(corr.read_text())["landmarks"]["chin"] and "nose_tip" in ids
