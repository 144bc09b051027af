"""The compiled normals the extraction shades with are numpy's (animation.face_normals, vertex_normals), bit for
bit."""

import numpy as np
import pytest

from conftest import SAMPLE
from converter.animation import face_normals, vertex_normals
from converter.extract import unit_face_normals, unit_vertex_normals
from converter.formats import load


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_same_bits_as_numpy_including_degenerate_and_non_finite_triangles(dtype):
    rng = np.random.default_rng(7)
    frames = (rng.normal(size=(5, 40, 3)) * rng.choice([1e-3, 1.0, 1e3], size=(5, 40, 1))).astype(dtype)
    faces = rng.integers(0, 39, size=(120, 3))
    faces[:3] = [[0, 0, 1], [2, 2, 2], [3, 4, 3]]  # zero area: divided by 1, as numpy does
    frames[1, 5] = np.nan
    frames[2, 6, 1] = np.inf
    with np.errstate(invalid="ignore"):
        got, want = unit_face_normals(frames, faces), face_normals(frames, faces)
        got_v, want_v = unit_vertex_normals(frames, faces), vertex_normals(frames, faces)
    assert got.dtype == want.dtype == got_v.dtype == want_v.dtype == np.float32
    assert np.array_equal(got, want, equal_nan=True)
    assert np.isnan(want).any() and (want[:, :3] == 0).all()  # the cases above were exercised
    assert np.array_equal(got_v, want_v, equal_nan=True)
    assert np.isnan(want_v).any() and (want_v[:, 39] == 0).all()  # vertex 39 is in no face: length 0


def test_the_same_bits_as_numpy_on_the_sample():
    anim = load(SAMPLE)
    assert np.array_equal(unit_face_normals(anim.frames, anim.faces), face_normals(anim.frames, anim.faces))
    assert np.array_equal(unit_vertex_normals(anim.frames, anim.faces), vertex_normals(anim.frames, anim.faces))
