"""glTF skinning against positions worked out by hand (and with scipy's rotations), and on real rigged files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from converter.export.gltf_builder import ARRAY_BUFFER, GltfBuilder
from converter.formats import load
from converter.formats.gltf import load_gltf, parse_container
from tests.formats.helpers import TRI, add_track, skinned_triangle

HERE = Path(".")
# A 1 x 2 strip: bottom pair on joint 0, middle pair half and half, top pair on joint 1 (which sits at y = 1).
STRIP = np.float32([[-0.5, 0, 0], [0.5, 0, 0], [-0.5, 1, 0], [0.5, 1, 0], [-0.5, 2, 0], [0.5, 2, 0]])
STRIP_FACES = np.uint16([0, 1, 3, 0, 3, 2, 2, 3, 5, 2, 5, 4])
ON_JOINT1 = np.float32([0, 0, 0.5, 0.5, 1, 1])


def z_quat(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(h), math.cos(h)]


def translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def two_joint_strip(influence_sets: int = 1, morph: bool = False) -> tuple[GltfBuilder, int, int]:
    """The strip skinned to joint0 (under an 'armature' node at z = 5) and its child joint1 at y = 1.

    The mesh node sits under a parent moved by (100, 0, 0) and has its own scale 3: both must be ignored.
    Returns (builder, armature node, joint1 node).
    """
    b = GltfBuilder("tests")
    w1 = ON_JOINT1
    attrs = {"POSITION": b.accessor(STRIP, minmax=True, target=ARRAY_BUFFER)}
    if influence_sets == 1:
        attrs["JOINTS_0"] = b.accessor(np.uint8([[0, 1, 0, 0]] * 6), target=ARRAY_BUFFER)
        attrs["WEIGHTS_0"] = b.accessor(np.stack([1 - w1, w1, 0 * w1, 0 * w1], 1).astype(np.float32),
                                        target=ARRAY_BUFFER)
    else:  # joint 0 in set 0, joint 1 in set 1; ushort joints, normalised ubyte weights that sum to 256/255
        attrs["JOINTS_0"] = b.accessor(np.uint16([[0, 0, 0, 0]] * 6), target=ARRAY_BUFFER)
        attrs["JOINTS_1"] = b.accessor(np.uint16([[1, 0, 0, 0]] * 6), target=ARRAY_BUFFER)
        q0 = np.uint8(np.round((1 - w1) * 256).clip(0, 255))
        q1 = np.uint8(np.round(w1 * 256).clip(0, 255))
        zero = np.zeros(6, np.uint8)
        attrs["WEIGHTS_0"] = b.accessor(np.stack([q0, zero, zero, zero], 1), normalized=True, target=ARRAY_BUFFER)
        attrs["WEIGHTS_1"] = b.accessor(np.stack([q1, zero, zero, zero], 1), normalized=True, target=ARRAY_BUFFER)
    prim = {"attributes": attrs, "indices": b.accessor(STRIP_FACES)}
    mesh: dict = {"primitives": [prim]}
    if morph:  # lifts the top pair by 1 along y before skinning
        delta = np.zeros((6, 3), np.float32)
        delta[4:, 1] = 1
        prim["targets"] = [{"POSITION": b.accessor(delta, target=ARRAY_BUFFER)}]
        mesh["weights"] = [1.0]
    mesh_index = b.add("meshes", mesh)
    joint1 = b.add("nodes", {"name": "joint1", "translation": [0, 1, 0]})
    joint0 = b.add("nodes", {"name": "joint0", "children": [joint1]})
    armature = b.add("nodes", {"name": "armature", "translation": [0, 0, 5], "children": [joint0]})
    ibm = np.stack([np.linalg.inv(translation(0, 0, 5)), np.linalg.inv(translation(0, 1, 5))])
    skin = b.add("skins", {"joints": [joint0, joint1], "skeleton": joint0,
                           "inverseBindMatrices": b.accessor(ibm.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32),
                                                             "MAT4")})
    body = b.add("nodes", {"name": "body", "mesh": mesh_index, "skin": skin, "scale": [3, 3, 3]})
    holder = b.add("nodes", {"name": "holder", "translation": [100, 0, 0], "children": [body]})
    b.add("scenes", {"nodes": [holder, armature]})
    return b, armature, joint1


def expected_strip(deg: float, lift: float = 0.0, dz: float = 0.0) -> np.ndarray:
    """By hand: joint1 turned deg about z at (0, 1); weight w on it takes v to (1-w) v + w (p + R (v - p))."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    out = []
    for (x, y, _), w in zip(STRIP, ON_JOINT1):
        y = y + (lift if w == 1 else 0.0)
        rx, ry = c * x - s * (y - 1), s * x + c * (y - 1)
        out.append([(1 - w) * x + w * rx, (1 - w) * y + w * (1 + ry), dz])
    return np.array(out)


@pytest.mark.parametrize("sets", [1, 2])
def test_turning_one_joint_moves_exactly_its_vertices_by_the_hand_computed_amount(sets):
    b, armature, joint1 = two_joint_strip(sets)
    add_track(b, joint1, "rotation", [0, 1], [z_quat(0), z_quat(90)])
    anim = load_gltf(b.glb(), HERE, 2.0, "strip")
    assert anim.n_frames == 3
    for k, deg in enumerate([0, 45, 90]):
        np.testing.assert_allclose(anim.frames[k], expected_strip(deg), atol=2e-6)
    # the bottom pair (joint 0 only) never moves; at 90 degrees the top pair lies along -x from the joint
    np.testing.assert_array_equal(anim.frames[:, :2], np.broadcast_to(anim.frames[:1, :2], (3, 2, 3)))
    np.testing.assert_allclose(anim.frames[2, 4:], [[-1, 0.5, 0], [-1, 1.5, 0]], atol=2e-6)
    assert anim.extras["skinned_meshes"] == 1 and anim.extras["animated_nodes"] == ["joint1"]


def test_the_skeleton_roots_parent_moves_the_skin():
    b, armature, joint1 = two_joint_strip()
    add_track(b, armature, "translation", [0, 1], [[0, 0, 5], [0, 0, 7]])
    add_track(b, joint1, "rotation", [0, 1], [z_quat(0), z_quat(90)])
    anim = load_gltf(b.glb(), HERE, 1.0, "strip")
    np.testing.assert_allclose(anim.frames[1], expected_strip(90, dz=2), atol=2e-6)


def test_morph_targets_apply_before_the_skin():
    b, _, joint1 = two_joint_strip(morph=True)
    add_track(b, joint1, "rotation", [0, 1], [z_quat(0), z_quat(90)])
    anim = load_gltf(b.glb(), HERE, 1.0, "strip")
    # the top pair is lifted to y = 3 and then turned about (0, 1): (x, 3) -> (-2, 1 + x)
    np.testing.assert_allclose(anim.frames[1], expected_strip(90, lift=1), atol=2e-6)
    np.testing.assert_allclose(anim.frames[1, 4:], [[-2, 0.5, 0], [-2, 1.5, 0]], atol=2e-6)


def test_rest_pose_file_is_a_still_at_the_bind_pose():
    b, _, _ = two_joint_strip()
    anim = load_gltf(b.glb(), HERE, None, "strip")
    assert anim.n_frames == 1
    np.testing.assert_allclose(anim.frames[0], STRIP, atol=2e-6)


def test_missing_inverse_bind_matrices_are_identity_and_unweighted_vertices_stay():
    b, node, joints = skinned_triangle(weights=[[1, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]])
    b.doc["nodes"][joints[0]]["translation"] = [1, 2, 3]
    anim = load_gltf(b.glb(), HERE, None, "tri")
    np.testing.assert_allclose(anim.frames[0], [[1, 2, 3], [2, 2, 3], [0, 1, 0]], atol=1e-6)


def test_simple_skin_matches_scipy_rotations_at_its_keys(shared_data):
    path = shared_data / "real" / "SimpleSkin.gltf"
    anim = load(path, fps=2.0)
    doc, _ = parse_container(path.read_bytes())
    assert doc["skins"][0]["joints"] == [1, 2] and anim.n_frames == 12  # keys every 0.5 s up to 5.5 s
    rest = anim.frames[0]
    # joint 2 (the child, at (0, 1, 0) in the world) turns about z; vertex weights on it are 0, .25, .5, .75, 1 by
    # row. Its IBM is a translation, so a vertex fully on it turns about (0, 1, 0): pivot + R (rest - pivot).
    w1 = np.repeat([0, 0.25, 0.5, 0.75, 1.0], 2)
    keys = {2: [0, 0, 0.707, 0.707], 4: [0, 0, 0.383, 0.924], 8: [0, 0, -0.707, 0.707]}
    for k, q in keys.items():
        r = Rotation.from_quat(q).as_matrix()
        turned = (rest - [0, 1, 0]) @ r.T + [0, 1, 0]
        want = (1 - w1)[:, None] * rest + w1[:, None] * turned
        np.testing.assert_allclose(anim.frames[k], want, atol=1e-5)
    np.testing.assert_allclose(rest[::2, 0], -0.5)  # the IBMs shift the mesh by -0.5 in x at rest


def test_fox_every_clip_selectable_with_sane_bounds_and_motion(shared_data):
    path = shared_data / "real" / "Fox.glb"
    default = load(path)
    clips = default.extras["animations"]
    assert [c["name"] for c in clips] == ["Survey", "Walk", "Run"]
    assert all(c["channels"] >= 20 for c in clips)
    rest_lo, rest_hi = default.frames[0].min(0), default.frames[0].max(0)
    size = rest_hi - rest_lo
    assert 50 < size[1] < 120 and 100 < size[2] < 200  # a fox about 80 high and 155 long, y up, facing +z
    frames = {}
    for c in clips:
        anim = load(path, animation=c["name"])
        f = anim.frames
        assert anim.n_frames == math.floor(c["duration"] * anim.fps + 1e-3) + 1
        assert (f.min((0, 1)) > rest_lo - size).all() and (f.max((0, 1)) < rest_hi + size).all()
        assert f[:, :, 1].min() > -10  # feet stay near the ground (y = 0)
        assert np.abs(f - f[:1]).max() > 5  # it moves
        frames[c["name"]] = f
    assert not np.allclose(frames["Walk"][5], frames["Run"][5], atol=1)
    # the legs swing in Walk: the foot vertices' forward (z) extent changes over the cycle
    low = frames["Walk"][0, :, 1] < 5
    spread = frames["Walk"][:, low, 2].max(1) - frames["Walk"][:, low, 2].min(1)
    assert spread.max() - spread.min() > 5


def test_joints_outside_the_scene_tree_still_pose_the_skin():
    b, node, joints = skinned_triangle(n_joints=2, weights=[[0, 1, 0, 0]] * 3, joints=[[0, 1, 0, 0]] * 3)
    b.doc["nodes"][joints[0]]["translation"] = [0, 0, 4]  # the root joint of a chain that no scene lists
    b.doc["nodes"][joints[1]]["translation"] = [1, 0, 0]
    b.doc["scenes"][0]["nodes"] = [node]
    anim = load_gltf(b.glb(), HERE, None, "tri")
    np.testing.assert_allclose(anim.frames[0], TRI + [1, 0, 4], atol=1e-6)
