"""Automatic face definition tables and deformation on the ICT FaceKit head."""

from __future__ import annotations

import numpy as np
import pytest

from converter.mpeg4.deform import deform
from converter.mpeg4.tables import FaceDefTables, build_tables


@pytest.fixture(scope="module")
def ict(shared_data):
    from converter.formats.ictfacekit import load_ict_head
    from samples.ict_fdp import ict_fdp

    head = load_ict_head(shared_data / "ict_facekit")
    fdp = ict_fdp(shared_data / "ict_facekit")
    tables = build_tables(head.vertices, head.faces, fdp)
    return head, fdp, tables


def one(fap: int, value: float) -> np.ndarray:
    v = np.zeros((1, 68))
    v[0, fap - 1] = value
    return v


def moved(head, tables, fap, value):
    out = deform(head.vertices, tables, one(fap, value))[0]
    return out, out - head.vertices


def test_zero_stream_is_neutral(ict):
    head, _, tables = ict
    out = deform(head.vertices, tables, np.zeros((5, 68)))
    assert out.shape == (5, len(head.vertices), 3) and out.dtype == np.float32
    assert np.array_equal(out, np.broadcast_to(head.vertices, out.shape))


def test_open_jaw_lowers_chin_and_lower_teeth_only(ict):
    head, fdp, tables = ict
    value = 200.0
    out, d = moved(head, tables, 3, value)
    expected = value * fdp.fapu["MNS0"] / 1024
    chin = fdp.points["2.1"]
    assert -d[chin, 1] == pytest.approx(expected, rel=0.1)
    lower, upper = fdp.parts["lower_teeth"], fdp.parts["upper_teeth"]
    assert (d[lower, 1] < 0).all() and np.abs(d[upper]).max() == 0
    for fp in ("8.1", "9.3", "4.1", "3.1", "3.5"):  # upper lip, nose, brow, eyelid, eye stay
        assert np.linalg.norm(d[fdp.points[fp]]) < 0.05 * expected, fp
    assert -d[fdp.points["8.2"], 1] > 0.5 * expected  # the lower lip follows the jaw
    # the mouth corners move about half as much
    assert 0.1 * expected < -d[fdp.points["2.4"], 1] < 0.9 * expected


def test_translation_faps_move_their_point_the_right_way(ict):
    head, fdp, tables = ict
    cases = [(4, "2.2", 1, -1), (5, "2.3", 1, 1), (6, "2.4", 0, 1), (7, "2.5", 0, -1), (31, "4.1", 1, 1),
             (32, "4.2", 1, 1), (19, "3.1", 1, -1), (22, "3.4", 1, 1), (51, "8.1", 1, -1), (63, "9.3", 1, 1)]
    for fap, fp, axis, sign in cases:
        _, d = moved(head, tables, fap, 300)
        p = fdp.points[fp]
        assert sign * d[p, axis] > 0, (fap, fp)
        assert np.abs(d[p]).argmax() == axis, (fap, fp)
        # the largest displacement is near the feature point, not somewhere else on the head
        far = np.linalg.norm(head.vertices - head.vertices[p], axis=1) > 0.8 * fdp.fapu["ES0"]
        assert np.linalg.norm(d[far], axis=1).max() < 0.2 * np.linalg.norm(d[p]), (fap, fp)


def test_left_and_upper_stay_separate(ict):
    head, fdp, tables = ict
    _, d = moved(head, tables, 31, 400)  # left inner brow
    assert np.abs(d[fdp.points["4.2"]]).max() < 0.2 * np.abs(d[fdp.points["4.1"]]).max()
    _, d = moved(head, tables, 4, 400)  # upper inner lip: the lower lip (across the mouth opening) stays
    assert np.abs(d[fdp.points["2.3"], 1]) < 0.25 * np.abs(d[fdp.points["2.2"], 1])
    _, d = moved(head, tables, 19, 400)  # top left eyelid: the bottom lid stays
    assert np.abs(d[fdp.points["3.3"], 1]) < 0.25 * np.abs(d[fdp.points["3.1"], 1])


def test_eyeball_rotation_keeps_eye_on_sphere(ict):
    from converter.mpeg4.tables import sphere_center

    head, fdp, tables = ict
    eye = np.asarray(fdp.parts["left_eye"])
    c = tables.entries[23].pivot
    assert np.allclose(c, sphere_center(head.vertices[eye]))
    out, d = moved(head, tables, 23, 20000)  # 0.2 rad yaw to the face's left
    r0 = np.linalg.norm(head.vertices[eye] - c, axis=1)
    r1 = np.linalg.norm(out[eye] - c, axis=1)
    np.testing.assert_allclose(r1, r0, atol=1e-4)
    pupil = fdp.points["3.5"]
    assert d[pupil, 0] > 0.15 * r0.mean()  # the gaze turns to +x
    others = np.setdiff1d(np.arange(len(head.vertices)), eye)
    assert np.abs(d[others]).max() == 0
    out, d = moved(head, tables, 25, 20000)  # pitch: positive looks down
    assert d[pupil, 1] < 0


def test_head_rotation_is_rigid(ict):
    head, _, tables = ict
    v = one(48, 10000) + one(49, -15000) + one(50, 5000)
    out = deform(head.vertices, tables, v)[0]
    idx = np.random.default_rng(0).choice(len(head.vertices), 300, replace=False)
    a = np.linalg.norm(head.vertices[idx, None] - head.vertices[None, idx], axis=-1)
    b = np.linalg.norm(out[idx, None] - out[None, idx], axis=-1)
    np.testing.assert_allclose(a, b, atol=2e-4)
    assert np.abs(out - head.vertices).max() > 0.1


def test_frames_are_independent_and_linear(ict):
    head, _, tables = ict
    rng = np.random.default_rng(1)
    vals = np.zeros((4, 68))
    lin = [4, 5, 6, 12, 19, 31, 33, 39, 41, 51, 61]  # translation FAPs only: displacement is linear
    vals[:, np.array(lin) - 1] = rng.normal(0, 100, (4, len(lin)))
    batch = deform(head.vertices, tables, vals)
    for t in range(4):
        np.testing.assert_allclose(batch[t], deform(head.vertices, tables, vals[t:t + 1])[0], atol=1e-5)
    d1 = deform(head.vertices, tables, vals[:1])[0] - head.vertices
    d2 = deform(head.vertices, tables, 2 * vals[:1])[0] - head.vertices
    np.testing.assert_allclose(d2, 2 * d1, atol=1e-4)


def test_tables_save_load(ict, tmp_path):
    head, _, tables = ict
    p = tmp_path / "t.json"
    tables.save(p)
    back = FaceDefTables.load(p)
    assert set(back.entries) == set(tables.entries) and back.missing == tables.missing
    vals = np.zeros((2, 68))
    vals[:, [2, 5, 22, 30, 47]] = [[100, 50, 3000, 200, 1000], [-20, 10, -3000, 100, -500]]
    np.testing.assert_allclose(deform(head.vertices, back, vals), deform(head.vertices, tables, vals), atol=1e-4)
    p.write_text('{"format": "other"}')
    from converter.errors import InputError

    with pytest.raises(InputError, match="not a facesvg face definition tables"):
        FaceDefTables.load(p)


def test_bad_inputs(ict):
    from converter.errors import InputError

    head, _, tables = ict
    with pytest.raises(InputError, match="68"):
        deform(head.vertices, tables, np.zeros((3, 10)))
    with pytest.raises(InputError, match="rebuild"):
        deform(head.vertices[:10], tables, np.zeros((3, 68)))
