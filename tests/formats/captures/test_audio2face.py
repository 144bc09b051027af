"""Audio2Face export: weights, eye joints as yaw/pitch/roll radians, the jaw joint as jawOpen only when the weight is
missing; the cut of the real export, the full real export (shared), and bad input."""

import importlib
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from converter.blendshapes import rotations
from converter.errors import InputError
from converter.formats.captures import audio2face
from converter.formats.weights import parse_weights
from tests.data.captures import derive_a2f
from tests.formats.captures.layout_samples import others, read

FIXTURE = "a2f_charlie_cut.json"
REAL = "real/a2f_charlie_bsweight.json"


def doc() -> dict:
    return json.loads(read(FIXTURE))


def scipy_matrices(quats_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices from w-first quaternions by scipy (x, y, z, w order): a reference independent of ours."""
    return Rotation.from_quat(np.asarray(quats_wxyz)[:, [1, 2, 3, 0]]).as_matrix()


def test_cut_of_the_real_export():
    data = read(FIXTURE)
    d = doc()
    assert audio2face.LAYOUT.sniff(data)
    track = audio2face.LAYOUT.parse(data, FIXTURE)
    assert track.source == "audio2face-json" and track.names == d["facsNames"] and len(track.names) == 52
    assert track.n_frames == 8 and track.fps == 60.0 and track.duration == pytest.approx(8 / 60)
    np.testing.assert_allclose(track.values, d["weightMat"], atol=1e-7)
    assert 0 <= track.values.min() and track.values.max() <= 1
    # the file has a jawOpen weight, so the jaw joint adds nothing
    assert track.names.count("jawOpen") == 1
    rot = np.array(d["rotations"])
    for k, eye in ((1, track.eye_left), (2, track.eye_right)):
        assert d["joints"][k] in ("eye_L", "eye_R") and eye.shape == (8, 3) and eye.dtype == np.float32
        # the stage's own Ry(yaw) Rx(pitch) Rz(roll) rebuilds the quaternion's rotation (same axes, no swap)
        np.testing.assert_allclose(rotations(eye), scipy_matrices(rot[:, k]), atol=2e-6)
        assert np.abs(eye).max() < math.radians(10)  # eye turns of a few degrees, in radians
    assert track.head is None


def test_decomposition_matches_scipy_euler():
    rng = np.random.default_rng(7)
    ypr = rng.uniform([-1.2, -1.2, -1.2], [1.2, 1.2, 1.2], size=(50, 3))
    q_xyzw = Rotation.from_euler("YXZ", ypr).as_quat()  # intrinsic Y, X', Z'': R = Ry Rx Rz
    got = audio2face.ypr_from_quaternions(q_xyzw[:, [3, 0, 1, 2]])
    np.testing.assert_allclose(got, ypr, atol=1e-5)


def test_jaw_drives_jaw_open_when_the_weight_is_missing():
    d = doc()
    k = d["facsNames"].index("jawOpen")
    real_jaw_open = np.array(d["weightMat"])[:, k]
    del d["facsNames"][k]
    d["weightMat"] = [row[:k] + row[k + 1:] for row in d["weightMat"]]
    d["numPoses"] = 51
    track = audio2face.parse(json.dumps(d).encode(), "nojaw.json")
    assert track.names[-1] == "jawOpen" and len(track.names) == 52
    pitch = Rotation.from_quat(np.array(d["rotations"])[:, 0][:, [1, 2, 3, 0]]).as_euler("YXZ")[:, 1]
    np.testing.assert_allclose(track.values[:, -1], np.clip(pitch / math.radians(25), 0, 1), atol=1e-6)
    # near the take's widest opening the joint-derived weight is close to the one A2F solved
    assert np.abs(track.values[:, -1] - real_jaw_open).max() < 0.1


def test_export_without_joints_and_the_old_path():
    d = doc()
    for key in ("joints", "rotations", "translations"):
        del d[key]
    track = audio2face.parse(json.dumps(d).encode(), "old.json")
    assert track.eye_left is None and track.n_frames == 8
    # weights.py's JSON path reads Audio2Face through this module
    via_weights = parse_weights(read(FIXTURE), FIXTURE)
    ours = audio2face.parse(read(FIXTURE), FIXTURE)
    np.testing.assert_array_equal(via_weights.values, ours.values)
    np.testing.assert_array_equal(via_weights.eye_left, ours.eye_left)


def test_sniff_claims_only_audio2face():
    assert not any(audio2face.sniff(data) for data in others("audio2face-json").values())


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(rotations=d["rotations"][:7]), r"rotations has 7 frames but weightMat has 8; .*truncated"),
    (lambda d: d["rotations"][3].pop(), r"rotations frame 3 does not have one entry per joint \(3\)"),
    (lambda d: d["rotations"][2][1].pop(), r"rotations frame 2, joint 1 is not a list of 4 numbers"),
    (lambda d: d["rotations"][5][2].__setitem__(0, float("nan")), r"rotations frame 5, joint 2 holds NaN"),
    (lambda d: d["rotations"][0].__setitem__(0, [0, 0, 0, 0]), r"rotations frame 0, joint 'jaw' is a zero quaternion"),
    (lambda d: d["translations"][1][0].append(0.0), r"translations frame 1, joint 0 is not a list of 3 numbers"),
    (lambda d: d.pop("rotations"), "lists joints but has no rotations"),
    (lambda d: d["weightMat"][4].pop(), r"weightMat frame 4 has 51 values, expected 52"),
    (lambda d: d["weightMat"][6].__setitem__(3, float("nan")), r"weightMat frame 6, value 3 is NaN"),
    (lambda d: d.update(numFrames=800), r"numFrames is 800 but weightMat has 8 rows"),
    (lambda d: d.update(weightMat=[]), "weightMat must be a non-empty list"),
    (lambda d: d.update(facsNames=[]), "facsNames must be a non-empty list"),
    (lambda d: d.update(exportFps=0), "frame rate 0 is not a positive"),
])
def test_bad_exports(edit, message):
    d = doc()
    edit(d)
    with pytest.raises(InputError, match=message):
        audio2face.parse(json.dumps(d).encode(), "bad.json")


def test_truncated_and_empty():
    data = read(FIXTURE)
    with pytest.raises(InputError, match="not valid JSON.*truncated"):
        audio2face.parse(data[:5000], "cut.json")
    with pytest.raises(InputError, match="empty"):
        audio2face.parse(b"", "e.json")


@pytest.mark.shared
def test_full_real_export(shared_data):
    data = (shared_data / REAL).read_bytes()
    d = json.loads(data)
    track = audio2face.parse(data, "a2f_charlie_bsweight.json")
    assert track.n_frames == 800 and track.fps == 60.0 and track.duration == pytest.approx(800 / 60)
    np.testing.assert_allclose(track.values, d["weightMat"], atol=1e-7)
    rot = np.array(d["rotations"])
    np.testing.assert_allclose(rotations(track.eye_left), scipy_matrices(rot[:, 1]), atol=2e-6)
    np.testing.assert_allclose(rotations(track.eye_right), scipy_matrices(rot[:, 2]), atol=2e-6)
    assert math.radians(3) < np.abs(track.eye_left).max() < math.radians(10)
    # the committed cut is exactly what derive_a2f.py makes of the real file
    assert json.loads(read(FIXTURE)) == derive_a2f.cut(d)


def test_registered():
    registry = importlib.import_module("converter.formats.captures")
    layouts = getattr(registry, "LAYOUTS", ())
    assert audio2face.LAYOUT in (list(layouts.values()) if isinstance(layouts, dict) else list(layouts))
    assert registry.detect(read(FIXTURE)) == audio2face.LAYOUT
