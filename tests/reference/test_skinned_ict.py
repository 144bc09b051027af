"""The generated skinned ICT face (tests/reference/skinned_ict.py) through our glTF loader, without a browser.

The jaw is checked in the head's own frame, found from the vertices only the head moves (a rigid fit, scipy), so
the neck's turn drops out: there the chin must sit where a hand-made rotation about the jaw pivot puts it.
The three.js comparison of the same file is in test_threejs.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from converter.formats.gltf import load_gltf
from converter.formats.ictfacekit import load_ict_head
from samples.ict_region import face_region
from tests.reference import skinned_ict

HERE = Path(".")


@pytest.fixture(scope="module")
def head(shared_data):
    return load_ict_head(shared_data / "ict_facekit")


@pytest.fixture(scope="module")
def rest(head) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(neutral positions, skin weights, morph deltas (E, V, 3)) of the mesh's vertices, in the loader's order."""
    pieces = face_region(head, skinned_ict.TRIANGLES)
    ids = np.concatenate([p.ids for p in pieces])
    v = head.vertices[ids].astype(np.float64)
    deltas = np.stack([head.delta(name)[ids] for name in skinned_ict.EXPRESSIONS]).astype(np.float64)
    deltas[:, sum(len(p.ids) for p in pieces if p.node == "face"):] = 0  # the eyes carry no expression
    return v, skinned_ict.skin_weights(v), deltas


@pytest.fixture(scope="module")
def loaded(head):
    return {kind: load_gltf(skinned_ict.skinned_face(head, byte_weights=kind == "ubyte"), HERE, None, "ict")
            for kind in ("float", "ubyte")}


def in_head_frame(frame: np.ndarray, rest_v: np.ndarray, on_head: np.ndarray) -> np.ndarray:
    """frame's positions moved so its head-only vertices sit back on their rest positions (least-squares rigid)."""
    a, b = frame[on_head].astype(np.float64), rest_v[on_head]
    rot, _ = Rotation.align_vectors(b - b.mean(0), a - a.mean(0))
    return rot.apply(frame - a.mean(0)) + b.mean(0)


def test_the_jaw_turns_about_its_pivot_in_the_heads_frame(loaded, rest):
    v, w, deltas = rest
    anim = loaded["float"]
    assert anim.frames.shape == (skinned_ict.FPS * 2 + 1, len(v), 3)
    np.testing.assert_allclose(anim.frames[0], v, atol=1e-4)  # the bind pose, every morph weight 0
    on_head, on_jaw = w[:, 2] == 1, w[:, 3] == 1
    assert on_head.sum() > 200 and on_jaw.sum() > 50
    for k in (15, 30, 45):
        t = k / skinned_ict.FPS
        phase = 2 * np.pi * t / skinned_ict.DURATION
        morphed = v + np.tensordot([np.sin(phase) ** 2, max(np.sin(phase / 2), 0), t / skinned_ict.DURATION],
                                   deltas, 1)  # the clip's morph weights at t
        deg = 20 * np.sin(phase / 2) ** 2
        local = in_head_frame(anim.frames[k], morphed, on_head)
        np.testing.assert_allclose(local[on_head], morphed[on_head], atol=2e-3)  # the fit holds: the head is rigid
        want = Rotation.from_euler("x", deg, degrees=True).apply(morphed[on_jaw] - skinned_ict.JAW) + skinned_ict.JAW
        np.testing.assert_allclose(local[on_jaw], want, atol=2e-3)
        chin_drop = morphed[on_jaw, 1].mean() - local[on_jaw, 1].mean()
        assert chin_drop > 0.5 * deg / 20  # the jaw opens (down), centimetres at 20 degrees
    # the neck turns the whole head: at 0.5 s (yaw 30 degrees) the head's vertices move centimetres in the world
    assert np.median(np.linalg.norm(anim.frames[15][on_head] - v[on_head], axis=1)) > 2


def test_byte_weights_pose_the_face_as_the_float_weights_do(loaded):
    a, b = loaded["float"].frames, loaded["ubyte"].frames
    assert np.abs(a - a[:1]).max() > 3  # it moves
    # 1/255 of weight on a ~15 cm lever, at most 2 joints' worth of rounding
    assert np.abs(a - b).max() < 0.15
