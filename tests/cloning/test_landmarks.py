"""Automatic landmarks on unseen faces: face-only masks, mm/cm/m units, with or without eyes and mouth interior.

References are independent of our rules: the ICT FaceKit's own 68 iBUG landmark vertices
(vertex_indices.json) and MediaPipe's canonical-mesh landmark ids.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from converter import formats
from converter.animation import FaceAnimation, Part
from converter.cloning import clone, dense, landmarks
from converter.errors import InputError
from converter.formats.ictfacekit import load_ict_head

# Our landmark -> iBUG 68 ids on the ICT head (mean of several ids), and its tolerance as a fraction of the
# nasion-to-menton height. The chin rule finds the forward-most chin point (pogonion), iBUG 8 is the lowest one
# (menton): 0.13 heights apart on the ICT head.
IBUG = {"nose_tip": ([30], 0.05), "nose_top": ([27], 0.07), "nose_bottom": ([33], 0.06), "lip_top": ([51], 0.04),
        "mouth": ([62, 66], 0.03), "lip_bottom": ([57], 0.05), "chin": ([8], 0.15),
        "eye_socket_left": ([39], 0.06), "eye_socket_right": ([42], 0.06),
        "mouth_side_left": ([48], 0.08), "mouth_side_right": ([54], 0.08)}
# The same on MediaPipe's canonical face (ids of its 468-point topology: 168 nasion, 4 pronasale, 164 subnasale,
# 0/17 outer lip centres, 13/14 inner lips, 199 chin front, 152 menton for the height, 133/362 inner eye
# corners, 61/291 mouth corners).
MEDIAPIPE = {"nose_tip": ([4], 0.05), "nose_top": ([168], 0.05), "nose_bottom": ([164], 0.05),
             "lip_top": ([0], 0.05), "mouth": ([13, 14], 0.05), "lip_bottom": ([17], 0.05), "chin": ([199], 0.05),
             "eye_socket_left": ([133], 0.07), "eye_socket_right": ([362], 0.07),
             "mouth_side_left": ([61], 0.1), "mouth_side_right": ([291], 0.1)}
SKIN = (0.8, 0.6, 0.5)


def compact(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the vertices the faces use, renumbered."""
    used = np.unique(faces)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces].astype(np.int32)


@pytest.fixture(scope="module")
def ict(shared_data):
    h = load_ict_head(str(shared_data / "ict_facekit"))
    ids = json.loads((shared_data / "ict_facekit" / "vertex_indices.json").read_text())["idx_to_landmark_verts"]
    marks = h.vertices[ids].astype(np.float64)
    names = np.array([p.name for p in h.parts])[h.part_ids]
    # The front half: triangles in front of the plane through the face contour at the ears (iBUG 0 and 16).
    front = (h.vertices[h.faces][:, :, 2] > marks[[0, 16], 2].mean()).all(1)
    return dict(h=h, marks=marks, names=names, front=front, size=float(np.linalg.norm(marks[27] - marks[8])))


def variant(ict, kind: str, scale: float, offset=(0.0, 0.0, 0.0)) -> FaceAnimation:
    """A face derived from the ICT head: "head" (skin, eyes, mouth interior as parts), "mask" (front half, skin
    only), "mask_parts" (front half with eye and mouth parts) or "mask_one_part" (the same, all one part)."""
    h, names = ict["h"], ict["names"]
    keep = np.isin(names, ("skin", "eye", "iris", "mouth")) if kind != "mask" else names == "skin"
    if kind != "head":
        keep &= ict["front"]
    part_names = ("skin", "eye", "iris", "mouth")
    pid = np.searchsorted(part_names, names[keep], sorter=np.argsort(part_names))
    pid = np.argsort(part_names)[pid]
    if kind == "mask_one_part":
        pid[:] = 0
    parts = tuple(Part(n, SKIN) for n in part_names)
    v, f = compact(h.vertices * scale + np.asarray(offset), h.faces[keep])
    return FaceAnimation(v[None].astype(np.float32), f, pid.astype(np.int32), parts, 30.0, f"ict_{kind}")


VARIANTS = [("head", 1.0), ("mask", 1.0), ("mask", 10.0), ("mask", 0.01), ("mask_parts", 10.0),
            ("mask_one_part", 0.01)]


def detected(anim: FaceAnimation) -> dict[str, np.ndarray]:
    """The landmarks the dense method finds on a face (from the faces it would use)."""
    return landmarks.detect(anim.frames[0].astype(np.float64), dense.skin_faces(anim), anim.name)


@pytest.mark.parametrize("kind, scale", VARIANTS)
def test_ict_landmarks_land_on_its_own_ibug_points(ict, kind, scale):
    offset = np.array([0.3, 1.6, -0.2]) * scale * 10  # anywhere in space, not at the origin
    pts = detected(variant(ict, kind, scale, offset))
    for name, (ids, tol) in IBUG.items():
        assert name in pts, name
        ref = ict["marks"][ids].mean(0)
        err = np.linalg.norm((pts[name] - offset) / scale - ref) / ict["size"]
        assert err < tol, (name, err)


def test_ict_landmarks_are_the_same_on_every_variant_relative_to_face_size(ict):
    base = {k: p for k, p in detected(variant(ict, "mask", 1.0)).items() if k not in landmarks.EXTENT_POINTS}
    for kind, scale in VARIANTS:
        pts = detected(variant(ict, kind, scale))
        for name, p in base.items():
            if name.startswith("grid_") and name not in pts:
                continue  # a proportional point can fall off a cut mesh's edge
            # Grid points are rays at (x, y) in proportion to the found features; their z is wherever the
            # surface is (on the steep sides of the face a small shift in x, y moves it far).
            axes = slice(0, 2) if name.startswith("grid_") else slice(0, 3)
            assert np.linalg.norm(pts[name][axes] / scale - p[axes]) < 0.03 * ict["size"], (kind, scale, name)


@pytest.mark.parametrize("scale", [1.0, 10.0, 0.01])
def test_mediapipe_canonical_face(small_data, scale):
    face = formats.load(small_data / "mediapipe_canonical" / "canonical_face_model.obj")
    v = face.frames[0].astype(np.float64)
    size = np.linalg.norm(v[168] - v[152])
    pts = landmarks.detect(v * scale, face.faces, "canonical")
    for name, (ids, tol) in MEDIAPIPE.items():
        assert name in pts, name
        assert np.linalg.norm(pts[name] / scale - v[ids].mean(0)) / size < tol, name


def plane() -> tuple[np.ndarray, np.ndarray]:
    g = np.linspace(-1.0, 1.0, 30)
    x, y = np.meshgrid(g, g)
    q = np.arange(900).reshape(30, 30)[:-1, :-1].ravel()
    faces = np.concatenate([np.column_stack([q, q + 1, q + 31]), np.column_stack([q, q + 31, q + 30])])
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)]), faces


@pytest.mark.parametrize("case, message", [
    ("plane", r"'plane'.*no nose tip: the mesh is flat.*--correspondences"),
    ("sphere", r"'sphere'.*no nose bridge.*look down \+z with y up, or give --correspondences"),
])
def test_shapes_without_a_face_say_what_is_missing(case, message):
    if case == "plane":
        v, f = plane()
    else:
        s = trimesh.creation.icosphere(3, radius=90.0)
        v, f = s.vertices, s.faces
    with pytest.raises(InputError, match=message):
        landmarks.detect(v, f, case)


@pytest.mark.parametrize("kind", ["head", "mask"])
def test_face_looking_away_is_told_to_turn(ict, kind):
    face = variant(ict, kind, 10.0)
    away = face.with_frames(face.frames * np.float32([-1, 1, -1]), name="away")
    with pytest.raises(InputError, match=r"'away'.*no nose tip.*looks down -z; turn it 180 degrees about y"):
        detected(away)
    blender = face.with_frames(face.frames[:, :, [0, 2, 1]] * np.float32([1, -1, 1]), name="zup")
    with pytest.raises(InputError, match=r"'zup'.*z-up looking down -y"):
        detected(blender)


def test_clone_names_the_face_without_landmarks(sample_path):
    src = formats.load(sample_path).sliced(0, 3)
    v, f = plane()
    flat = FaceAnimation(v[None].astype(np.float32), f.astype(np.int32), np.zeros(len(f), np.int32),
                         (Part("skin", SKIN),), 30.0, "flat_card")
    with pytest.raises(InputError, match=r"'flat_card'.*no nose tip.*--correspondences"):
        clone(src, flat, "dense")


def test_sample_animation_cloned_onto_mm_face_mask(ict, sample_path):
    src = formats.load(sample_path)
    target = variant(ict, "mask", 10.0)  # front half, no eyes or mouth interior, millimetres
    out = clone(src, target, "dense")
    assert out.frames.shape == (src.n_frames, target.n_vertices, 3)
    assert np.isfinite(out.frames).all()
    np.testing.assert_allclose(out.frames[0], target.frames[0], atol=1e-3)
    motion = np.linalg.norm(out.frames - out.frames[0], axis=-1)  # (T, V) in mm
    marks = ict["marks"]  # the sample is a simplified ICT head, in the same centimetre frame

    def regions(frames: np.ndarray, unit: float, ids: np.ndarray) -> tuple[float, float]:
        """Peak motion (in cm) around the mouth and on the forehead, averaged over their vertices."""
        base = frames[0, ids] / unit
        m = np.linalg.norm(frames[:, ids] - frames[0, ids], axis=-1).max(0) / unit
        mouth = np.linalg.norm(base - marks[[48, 54, 51, 57]].mean(0), axis=1) < 0.15 * ict["size"]
        forehead = base[:, 1] > marks[27, 1] + 0.4 * ict["size"]
        return float(m[mouth].mean()), float(m[forehead].mean())

    out_mouth, out_brow = regions(out.frames, 10.0, np.arange(out.n_vertices))
    src_mouth, src_brow = regions(src.frames, 1.0, np.unique(dense.skin_faces(src)))
    # The mask's mouth moves as much as the sample's (to within a factor 1.5, in the mask's millimetres), and
    # the forehead keeps its share of the motion.
    assert src_mouth / 1.5 < out_mouth < 1.5 * src_mouth, (out_mouth, src_mouth)
    assert 0.5 < (out_mouth / out_brow) / (src_mouth / src_brow) < 2.0, (out_mouth, out_brow, src_mouth, src_brow)
    motion = np.linalg.norm(out.frames - out.frames[0], axis=-1).max(1)
    assert (motion > 0.1 * motion.max()).sum() > 0.3 * src.n_frames  # motion through the clip, not one spike
