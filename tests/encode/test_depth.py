"""Depth order: the z-buffer comparison can tell a wrong order, and layer copies fix a simple crossing."""

import numpy as np
import pytest

from bench.order_measure import order_error
from converter import extract
from converter.animation import FaceAnimation, Part
from converter.encode import order


def crossing(n_frames: int = 12) -> FaceAnimation:
    """Two overlapping squares facing the camera; the small one moves from behind the big one to in front."""
    big = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    small = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], float)
    z = np.linspace(-0.4, 0.4, n_frames)
    frames = np.stack([np.concatenate([big, small + [0.2, 0.1, dz]]) for dz in z])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)
    return FaceAnimation(frames.astype(np.float32), faces, np.array([0, 0, 1, 1], np.int32),
                         (Part("skin", (0.8, 0.6, 0.5)), Part("eye", (0.9, 0.9, 0.9))), 10.0, "crossing")


@pytest.fixture(scope="module")
def scene():
    anim = crossing()
    return anim, extract.extract(anim, extract.fit_camera(anim, 96, yaw=5.0), occlusion=False)


@pytest.mark.slow
def test_order_error_sees_a_wrong_fixed_order(scene):
    anim, sheet = scene
    back_first = order.DrawList(np.array([2, 3, 0, 1], np.int32), sheet.visible[:, [2, 3, 0, 1]])
    big_first = order.DrawList(np.array([0, 1, 2, 3], np.int32), sheet.visible[:, [0, 1, 2, 3]])
    # Early frames: the small square is behind, so drawing it last is wrong; late frames the reverse.
    early, late = [0, 1], [10, 11]
    assert order_error(anim.frames, sheet, back_first, early)["max"] < 0.02
    assert order_error(anim.frames, sheet, big_first, early)["max"] > 0.1
    assert order_error(anim.frames, sheet, big_first, late)["max"] < 0.02
    assert order_error(anim.frames, sheet, back_first, late)["max"] > 0.1


def test_layer_copies_fix_the_crossing(scene):
    anim, sheet = scene
    fixed = order.draw_list(sheet)
    layered = order.layered(sheet)
    frames = list(range(anim.n_frames))
    assert len(layered.triangles) > len(fixed.triangles) and layered.conflicts > 0
    assert order_error(anim.frames, sheet, fixed, frames)["max"] > 0.1
    assert order_error(anim.frames, sheet, layered, frames)["max"] < 0.02
    # A triangle and its copy never show at the same frame.
    for t in np.unique(layered.triangles):
        assert layered.active[:, layered.triangles == t].sum(axis=1).max() <= 1
