"""Degenerate faces build a puppet or say why not (InputError): never a traceback, never a non-finite number."""

from __future__ import annotations

import numpy as np
import pytest

from converter.animation import Part
from converter.errors import InputError
from converter.formats.morphs import MorphFace
from converter.options import ConversionOptions, Report
from converter.puppet import pose, puppet_of
from converter.writers import puppet as writer

SKIN = (Part("skin", (0.8, 0.6, 0.5)),)


def face_of(base, faces, deltas, names=None) -> MorphFace:
    base = np.asarray(base, np.float32)
    deltas = np.asarray(deltas, np.float32)
    names = names or [f"t{k}" for k in range(len(deltas))]
    return MorphFace(base, deltas, names, np.asarray(faces, np.int32), np.zeros(len(faces), np.int32), SKIN)


def grid(n: int = 4):
    y, x = np.mgrid[0:n, 0:n] / (n - 1)
    v = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    f = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            f += [(a, a + 1, a + n), (a + 1, a + n + 1, a + n)]
    return v, np.array(f)


CASES = {
    "a point": lambda: face_of(np.zeros((3, 3)), [(0, 1, 2)], np.ones((1, 3, 3))),
    "a target that moves nothing": lambda: face_of(grid()[0], grid()[1], np.zeros((2, 16, 3))),
    "a target that flattens the face to a line": lambda: face_of(
        grid()[0], grid()[1], [np.c_[np.zeros(16), -grid()[0][:, 1], np.zeros(16)]]),
    "a target that sends the face behind the camera": lambda: face_of(
        grid()[0], grid()[1], [np.tile([0.0, 0.0, 50.0], (16, 1))]),
    "facing away": lambda: face_of(grid()[0], grid()[1][:, ::-1], np.ones((1, 16, 3)) * 0.1),
}


@pytest.mark.parametrize("case", CASES)
def test_degenerate_face(case):
    face = CASES[case]()
    try:
        puppet = puppet_of(face, ConversionOptions(size=64))
    except InputError as exc:
        assert case in ("a point", "facing away"), exc  # nothing to see: said in one sentence
        assert str(exc).strip().endswith(".")
        return
    for w in (0.0, 0.5, 1.0, 3.0):
        xy, z = pose(puppet, np.full(len(puppet.morphs), w), head=(0.3, -0.2, 0.1), eyes=(0.1, 0.1, 0.1, 0.1))
        assert xy.shape == (len(puppet.xy), 2) and np.isfinite(xy).all() and np.isfinite(z).all()
        assert np.isfinite(puppet.xy).all() and all(np.isfinite(p.table.xy).all() for p in puppet.morphs)
    page = writer.write(puppet, ConversionOptions(), Report())
    meta, _, _, _ = writer.read_blocks(page)
    assert meta["triangles"] == len(puppet.triangles)
