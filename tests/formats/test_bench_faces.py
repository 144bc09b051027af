"""The benchmark faces built from the ICT head: sizes, frames, motion, determinism."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = [pytest.mark.usefixtures("shared_data"), pytest.mark.slow]


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Kabsch: the rotation taking centred points a onto centred points b."""
    a, b = a - a.mean(0), b - b.mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1, 1, d]) @ u.T


def test_ict_bench_face_size_motion_and_determinism():
    from bench.faces import ict_bench_face

    a = ict_bench_face()
    assert a.n_faces >= 5000 and a.n_frames >= 300 and a.fps == 30.0
    assert {p.name for p in a.parts} >= {"skin", "mouth", "teeth", "eye", "iris"}
    # Eyes carry no expression: their motion is the head rotation alone. Yaw reaches ~15 degrees.
    eyes = np.unique(a.faces[np.isin(a.part_ids, [i for i, p in enumerate(a.parts) if p.name in ("eye", "iris")])])
    yaws = []
    for k in range(0, a.n_frames, 5):
        r = rotation_between(a.frames[0, eyes], a.frames[k, eyes])
        yaws.append(np.degrees(np.arctan2(r[0, 2], r[2, 2])))
    assert 13 < max(np.abs(yaws)) <= 15.5
    # Expressions vary: the mouth region moves by centimetres beyond the rigid head motion.
    skin = np.unique(a.faces[a.part_ids == 0])
    assert np.ptp(a.frames[:, skin, 1], axis=0).max() > 2.0
    assert np.array_equal(ict_bench_face(n_frames=20).frames, a.frames[:20])


def test_chapter_face_matches_the_chapter_size():
    from bench.faces import chapter_face

    c = chapter_face()
    assert (c.n_frames, c.fps) == (207, 25.0) and abs(c.duration - 8.28) < 1e-9
    assert 440 <= c.n_faces <= 530
