"""The compiled face normals the extraction shades with are numpy's (animation.face_normals), bit for bit."""

import numpy as np
import pytest

from conftest import SAMPLE
from converter.animation import face_normals
from converter.extract import unit_face_normals
from converter.formats import load


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_same_bits_as_numpy_including_degenerate_and_non_finite_triangles(dtype):
    rng = np.random.default_rng(7)
    frames = (rng.normal(size=(5, 40, 3)) * rng.choice([1e-3, 1.0, 1e3], size=(5, 40, 1))).astype(dtype)
    faces = rng.integers(0, 40, size=(120, 3))
    faces[:3] = [[0, 0, 1], [2, 2, 2], [3, 4, 3]]  # zero area: divided by 1, as numpy does
    frames[1, 5] = np.nan
    frames[2, 6, 1] = np.inf
    with np.errstate(invalid="ignore"):
        got, want = unit_face_normals(frames, faces), face_normals(frames, faces)
    assert got.dtype == want.dtype == np.float32
    assert np.array_equal(got, want, equal_nan=True)
    assert np.isnan(want).any() and (want[:, :3] == 0).all()  # the cases above were exercised


def test_the_same_bits_as_numpy_on_the_sample():
    anim = load(SAMPLE)
    assert np.array_equal(unit_face_normals(anim.frames, anim.faces), face_normals(anim.frames, anim.faces))
