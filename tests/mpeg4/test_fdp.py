"""FDP JSON and Xface .fdp import, FAPU from feature points, the bundled FDPs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.mpeg4.fdp import Fdp, fapu_from_points, fdp_to_json, load_fdp, save_fdp
from converter.mpeg4.standard import FEATURE_POINTS, fap_table, fapu_scale

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def test_fap_table_facts():
    t = fap_table()
    assert len(t) == 68 and t[2].name == "open_jaw" and t[2].unit == "MNS" and t[2].fdp == "2.1"
    assert t[18].unit == "IRISD"  # FAP 19 close_t_l_eyelid: IRISD, not MNS
    assert sum(f.is_translation for f in t) == 56
    assert {f.unit for f in t} == {"na", "MNS", "MW", "IRISD", "AU", "ES", "ENS"}
    s = fapu_scale({"MNS0": 1024.0, "MW0": 2048.0})
    assert s[2] == 1.0 and s[5] == 2.0 and s[22] == 1e-5 and s[0] == 0


def test_xface_fdp_import(small_data):
    fdp = load_fdp(small_data / "mpeg4" / "xface" / "alice.fdp")
    assert fdp.fapu == {"IRISD0": 16.0, "ES0": 69.0, "ENS0": 51.0, "MNS0": 30.0, "MW0": 50.0}
    x = fdp.extra["xface"]
    assert len(x["submesh"]) == 33  # 35 listings; 2.1 and one more are listed for two submeshes
    assert x["face_submesh"] == "alice.wrl_3"
    # vertex ids only from the face submesh: the left pupil (3.5) is on the eye submesh, so not a face vertex
    assert fdp.points["2.1"] == 2395 and "3.5" not in fdp.points
    assert len(fdp.points) == sum(any(m == "alice.wrl_3" for m, _ in lst) for lst in x["submesh"].values())
    assert x["submesh"]["3.5"] == [["alice.wrl_1", 19]]
    assert x["submesh"]["2.1"] == [["alice.wrl_3", 2395], ["alice.wrl_5", 0]]
    assert x["pivots"]["LeftEye"] == [-33.8, -33.2, -28.8]
    assert [2, "RaisedCosInfluenceSph", 0.3] in x["influences"]["2.1"]


def test_xface_fdp_bad_xml(tmp_path):
    p = tmp_path / "bad.fdp"
    p.write_text("<xfdp><head><fapu ES0='x'/></head></xfdp>")
    with pytest.raises(InputError, match="FAPU ES0"):
        load_fdp(p)
    p.write_text("<xfdp><fdp name='99.1' index='3'/></xfdp>")
    with pytest.raises(InputError, match="line 1"):
        load_fdp(p)
    p.write_text("<xfdp><fdp name='2.1'")
    with pytest.raises(InputError, match="not valid XML"):
        load_fdp(p)


def test_json_round_trip_and_ranges(tmp_path):
    fdp = Fdp({"2.1": 5, "3.5": 7}, {"left_eye": [10, 11, 12, 13, 20], "tongue": []}, {"ES0": 6.5},
              {"7.1": [0.0, -1.0, 2.5]}, 100, "test")
    p = tmp_path / "a.fdp.json"
    save_fdp(fdp, p)
    data = json.loads(p.read_text())
    assert data["parts"]["left_eye"] == [[10, 14], 20]
    back = load_fdp(p)
    assert back.points == fdp.points and back.parts["left_eye"] == [10, 11, 12, 13, 20]
    assert back.positions == fdp.positions and back.fapu == fdp.fapu and back.vertex_count == 100
    assert fdp_to_json(back) == fdp_to_json(fdp)


@pytest.mark.parametrize("data,word", [
    ({"points": {"12.1": 3}}, "not an MPEG-4 feature point"),
    ({"points": {"2.1": -3}}, "vertex index"),
    ({"points": {"2.1": "3"}}, "vertex index"),
    ({"points": {}, "parts": {"tongue": [[5]]}}, "ranges"),
    ({"points": {}, "fapu": {"XX0": 3}}, "fapu"),
    ({"nothing": 1}, "points"),
])
def test_json_errors(tmp_path, data, word):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(data))
    with pytest.raises(InputError, match=word):
        load_fdp(p)


def test_vertex_checks(tmp_path):
    p = tmp_path / "a.json"
    p.write_text(json.dumps({"points": {"2.1": 50}}))
    with pytest.raises(InputError, match="vertex 50"):
        load_fdp(p, np.zeros((10, 3)))
    p.write_text(json.dumps({"points": {"2.1": 5}, "vertex_count": 99}))
    with pytest.raises(InputError, match="99 vertices"):
        load_fdp(p, np.zeros((10, 3)))
    p.write_text("not json")
    with pytest.raises(InputError, match="neither"):
        load_fdp(p)
    p.write_text("{bad json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_fdp(p)


def test_fapu_from_points():
    pts = {"3.1": [3, 1.2, 0], "3.3": [3, 0.2, 0], "3.5": [3, 1, 0], "3.6": [-3, 1, 0], "9.15": [0, -4, 1],
           "2.2": [0, -6, 1], "8.3": [2.5, -6.5, 0], "8.4": [-2.5, -6.5, 0]}
    f = fapu_from_points(None, {k: np.array(v, float) for k, v in pts.items()})
    assert f == pytest.approx({"IRISD0": 1.0, "ES0": 6.0, "ENS0": 5.0, "MNS0": 2.0, "MW0": 5.0})
    del pts["8.3"]
    pts.update({"2.4": [2, -6, 0], "2.5": [-2, -6, 0]})
    assert fapu_from_points(None, {k: np.array(v, float) for k, v in pts.items()})["MW0"] == pytest.approx(4.0)


def _mirror_ok(fdp: Fdp, v: np.ndarray, tol: float) -> None:
    """Left points have x > 0 and mirror their right partner."""
    pairs = [("2.4", "2.5"), ("3.1", "3.2"), ("3.5", "3.6"), ("3.7", "3.8"), ("4.1", "4.2"), ("4.5", "4.6"),
             ("5.1", "5.2"), ("8.3", "8.4"), ("9.1", "9.2")]
    pos = fdp.point_positions(v)
    for left, right in pairs:
        assert pos[left][0] > 0 > pos[right][0], (left, right)
        assert np.abs(pos[left] * [-1, 1, 1] - pos[right]).max() < tol, (left, right)


def test_ict_fdp_matches_bundled_and_is_sane(shared_data):
    from converter.formats.ictfacekit import load_ict_head
    from samples.ict_fdp import ict_fdp

    fdp = ict_fdp(shared_data / "ict_facekit")
    assert fdp_to_json(fdp) == (ROOT / "samples" / "ict.fdp.json").read_text()  # regenerate with samples/make_fdp.py
    v = load_ict_head(shared_data / "ict_facekit").vertices
    assert set(fdp.points) <= set(FEATURE_POINTS) and len(fdp.points) >= 60
    _mirror_ok(fdp, v, 0.05)
    p = fdp.point_positions(v)
    assert (p["2.1"][1] < p["8.2"][1] < p["2.3"][1] <= p["2.2"][1] < p["8.1"][1] < p["9.15"][1] < p["3.5"][1]
            < p["4.3"][1])
    assert 0.6 < fdp.fapu["IRISD0"] < 1.5 and 5 < fdp.fapu["ES0"] < 8 and 4 < fdp.fapu["MW0"] < 6  # cm
    assert set(fdp.parts) == {"left_eye", "right_eye", "upper_teeth", "lower_teeth", "tongue"}
    assert v[fdp.parts["left_eye"]][:, 0].min() > 0
    assert v[fdp.parts["lower_teeth"]][:, 1].mean() < v[fdp.parts["upper_teeth"]][:, 1].mean()


def test_mediapipe_fdp(small_data):
    from converter.formats.obj import parse_obj
    from converter.mpeg4.facepoints import mediapipe_fdp

    obj = small_data / "mediapipe_canonical" / "face_model_with_iris.obj"
    fdp = mediapipe_fdp(obj)
    assert fdp_to_json(fdp) == (ROOT / "samples" / "mediapipe.fdp.json").read_text()
    v = parse_obj(obj.read_text())[0]
    _mirror_ok(fdp, v, 1e-3)
    assert fdp.parts["left_eye"] == [473, 474, 475, 476, 477]
    assert set(fdp.fapu) == {"IRISD0", "ES0", "ENS0", "MNS0", "MW0"}
    # the pupils come from the iris centres, the inner lip points from the inner contour
    assert fdp.points["3.5"] == 473 and abs(v[fdp.points["2.2"], 1] - v[13, 1]) < 1e-6


def test_sample_fdp_fits_sample(sample_path):
    from converter import formats

    fdp = load_fdp(ROOT / "samples" / "face.fdp.json")
    face = formats.load(sample_path)
    fdp.check(face.n_vertices)
    assert fdp.vertex_count == face.n_vertices
    assert {"left_eye", "right_eye", "upper_teeth", "lower_teeth"} <= set(fdp.parts)
    _mirror_ok(fdp, face.frames[0], 0.6)
