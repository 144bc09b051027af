"""VRM avatars: morph names wherever exporters put them, VRM 0.x / 1.0 expressions as weighted targets, and ARKit
captures driving them (by name on perfect-sync avatars, through the ARKit-to-VRM table on plain ones)."""

import json
from pathlib import Path

import numpy as np
import pytest

from converter import blendshapes, verify
from converter.cli import main
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.formats.gltf import load_gltf
from converter.formats.gltf.names import target_names
from converter.formats.morphs import from_gltf, load_morph_face
from converter.formats.weights import WeightTrack, parse_weights, read_weights

BASE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
# Three targets whose deltas and bind weights are dyadic: every weighted sum below is exact in float32.
D = np.array([
    [[0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0]],
    [[0, 0, 0], [0.5, 0, 0], [0, 0, 0], [0, 0, 0.25]],
    [[0, 0, 0], [0, 0, 0], [0, 0.25, 0], [0, 0, 2]],
], np.float32)
RAW = ["mouthOpen", "smileA", "eyeClose_L"]


def face_doc(names_at: str = "primitive", raw=RAW, deltas=D) -> tuple[GltfBuilder, int, int]:
    """Two triangles with len(raw) morph targets on one node; names stored where names_at says."""
    b = GltfBuilder("tests")
    prim = {"attributes": {"POSITION": b.accessor(BASE, minmax=True, target=ARRAY_BUFFER)},
            "indices": b.accessor(np.array([0, 1, 2, 1, 3, 2], np.uint16), target=ELEMENT_ARRAY_BUFFER),
            "targets": [{"POSITION": b.accessor(d, minmax=True)} for d in deltas]}
    mesh = {"name": "Face", "primitives": [prim]}
    if names_at == "primitive":  # UniVRM 0.x
        prim["extras"] = {"targetNames": list(raw)}
    elif names_at == "mesh":
        mesh["extras"] = {"targetNames": list(raw)}
    elif names_at == "target":  # UniVRM before 0.36: targets[k].extra.name
        for t, n in zip(prim["targets"], raw):
            t["extra"] = {"name": n}
    m = b.add("meshes", mesh)
    node = b.add("nodes", {"name": "Face", "mesh": m})
    b.add("scenes", {"nodes": [node]})
    return b, m, node


def v0(groups: list[dict], **kw) -> bytes:
    b, m, _ = face_doc(**kw)
    for g in groups:
        for bind in g.get("binds", []) if isinstance(g, dict) else ():
            bind.setdefault("mesh", m)
    b.doc["extensions"] = {"VRM": {"specVersion": "0.0", "blendShapeMaster": {"blendShapeGroups": groups}}}
    b.use_extension("VRM", required=False)
    return b.glb()


def v1(preset: dict, custom: dict | None = None, **kw) -> bytes:
    b, _, node = face_doc(**kw)
    for e in [*preset.values(), *(custom or {}).values()]:
        for bind in e.get("morphTargetBinds", []):
            bind.setdefault("node", node)
    b.doc["extensions"] = {"VRMC_vrm": {"specVersion": "1.0", "expressions": {"preset": preset,
                                                                              "custom": custom or {}}}}
    b.use_extension("VRMC_vrm", required=False)
    return b.glb()


def face_of(data: bytes):
    return from_gltf(data, Path("."), name="avatar")


def delta(face, name: str) -> np.ndarray:
    return face.deltas[face.names.index(name)]


def track(rows: dict[str, list[float]], fps: float = 30.0) -> WeightTrack:
    names = list(rows)
    values = np.array([rows[n] for n in names], np.float32).T
    return WeightTrack(names, np.arange(len(values)) / fps, values, fps)


V0_GROUPS = [
    {"name": "Neutral", "presetName": "neutral", "binds": []},
    {"name": "A", "presetName": "a", "binds": [{"index": 0, "weight": 100}]},
    {"name": "Joy", "presetName": "joy", "binds": [{"index": 1, "weight": 50}, {"index": 2, "weight": 25}]},
    {"name": "Blink_L", "presetName": "blink_l", "isBinary": True, "binds": [{"index": 2, "weight": 100}]},
    {"name": "Smirk", "presetName": "unknown", "binds": [{"index": 1, "weight": 75}],
     "materialValues": [{"materialName": "Face", "propertyName": "_Color", "targetValue": [1, 0, 0, 1]}]},
]


# -- names ------------------------------------------------------------------------------------------------------


def test_target_names_from_mesh_then_primitive_then_each_target():
    targets = [{"POSITION": 1}, {"POSITION": 2}]
    assert target_names({"extras": {"targetNames": ["a", "b"]},
                         "primitives": [{"targets": targets, "extras": {"targetNames": ["x", "y"]}}]}) == ["a", "b"]
    assert target_names({"primitives": [{"targets": targets, "extras": {"targetNames": ["x"]}}]}) == ["x", ""]
    per_target = [{"POSITION": 1, "extra": {"name": "old"}}, {"POSITION": 2, "extras": {"name": "new"}}]
    assert target_names({"primitives": [{"targets": per_target}]}) == ["old", "new"]
    assert target_names({"primitives": [{"targets": targets}]}) == ["", ""]
    assert target_names({"extras": {"targetNames": "not a list"}, "primitives": [{"targets": targets}]}) == ["", ""]
    assert target_names({}) == [] and target_names({"primitives": [{}]}) == []


@pytest.mark.parametrize("names_at", ["mesh", "primitive", "target"])
def test_both_readers_get_the_names_wherever_they_are(names_at):
    b, _, _ = face_doc(names_at)
    data = b.glb()
    anim = load_gltf(data, Path("."), name="face")
    assert anim.extras["morph_targets"] == RAW
    assert anim.extras["node_tree"][0][3] == tuple(RAW)  # what framing reads
    face = face_of(data)
    assert face.names == RAW and not face.expressions
    for k, name in enumerate(RAW):
        assert np.array_equal(delta(face, name), D[k])


# -- expressions ------------------------------------------------------------------------------------------------


def test_vrm0_groups_are_targets_summing_their_binds_weight_over_100():
    face = face_of(v0([dict(g, binds=[dict(x) for x in g["binds"]]) for g in V0_GROUPS]))
    assert face.names == RAW + ["neutral", "aa", "happy", "blinkLeft", "Smirk"]
    assert np.array_equal(delta(face, "aa"), D[0])
    assert np.array_equal(delta(face, "happy"), 0.5 * D[1] + 0.25 * D[2])
    assert np.array_equal(delta(face, "Smirk"), 0.75 * D[1])
    assert not delta(face, "neutral").any()
    kinds = {face.names[x.index]: (x.expression.preset, x.expression.binary, x.bound) for x in face.expressions}
    assert kinds == {"neutral": (True, False, ()), "aa": (True, False, (0,)), "happy": (True, False, (1, 2)),
                     "blinkLeft": (True, True, (2,)), "Smirk": (False, False, (1,))}
    assert face.extras["vrm_expressions"] == ["neutral", "aa", "happy", "blinkLeft", "Smirk"]
    assert any("Smirk" in w and "materials" in w for w in face.extras["warnings"])  # not silently ignored
    info = load_gltf(v0([dict(g, binds=[dict(x) for x in g["binds"]]) for g in V0_GROUPS]), Path(".")).extras
    assert info["vrm_expressions"] == face.extras["vrm_expressions"] and info["vrm_material_binds_not_drawn"] == [
        "Smirk"]


def test_vrm1_presets_and_customs_weigh_their_binds_as_given():
    preset = {"aa": {"morphTargetBinds": [{"index": 0, "weight": 0.5}, {"index": 2, "weight": 0.25}]},
              "blink": {"isBinary": True, "morphTargetBinds": [{"index": 2}]},  # weight defaults to 1
              "smile": {"morphTargetBinds": [{"index": 1}]}}  # not a preset: ignored
    custom = {"cheek": {"morphTargetBinds": [{"index": 1, "weight": 0.75}], "materialColorBinds": [{}]},
              "happy": {"morphTargetBinds": [{"index": 1}]}}  # a custom may not take a preset name: ignored
    face = face_of(v1(preset, custom))
    assert face.names == RAW + ["aa", "blink", "cheek"]
    assert np.array_equal(delta(face, "aa"), 0.5 * D[0] + 0.25 * D[2])
    assert np.array_equal(delta(face, "blink"), D[2])
    assert np.array_equal(delta(face, "cheek"), 0.75 * D[1])
    notes = " ".join(face.extras["warnings"])
    assert "'smile' is ignored" in notes and "'happy' is ignored" in notes and "cheek" in notes


def test_an_expression_named_like_a_raw_morph_keeps_both_and_wins_by_name():
    raw = ["aa", "smileA", "eyeClose_L"]
    face = face_of(v1({"aa": {"morphTargetBinds": [{"index": 0, "weight": 0.5}]}}, raw=raw))
    assert face.names == raw + ["vrm:aa"]
    m = blendshapes.match_face(["AA", "smileA"], face)
    assert m.mapping.tolist() == [[0, 0, 0, 1], [0, 1, 0, 0]]


def test_bad_binds_are_skipped_with_a_note():
    groups = [{"name": "A", "presetName": "a", "binds": [{"index": 9, "weight": 100}, {"index": "0"},
                                                          {"index": 0, "weight": "x"}, {"index": 0, "weight": 50}]},
              {"presetName": "unknown"}, "junk", {"name": "A2", "presetName": "a", "binds": []}]
    face = face_of(v0(groups))
    assert face.names == RAW + ["aa"]
    assert np.array_equal(delta(face, "aa"), 0.5 * D[0])
    notes = " ".join(face.extras["warnings"])
    assert notes.count("names no morph target") == 3 and "no name" in notes and "earlier group" in notes


# -- driving ----------------------------------------------------------------------------------------------------


def test_an_arkit_capture_drives_a_plain_vrm_face_through_the_table():
    face = face_of(v0([dict(g, binds=[dict(x) for x in g["binds"]]) for g in V0_GROUPS]))
    t = track({"jawOpen": [0, 0.5, 1, 0.25], "eyeBlinkLeft": [0, 0.4, 0.6, 1], "mouthSmileLeft": [0, 1, 0.5, 0],
               "mouthSmileRight": [0, 1, 0, 0], "cheekPuff": [0, 1, 1, 1]})
    m = blendshapes.match_face(t.names, face)
    assert m.route == "vrm-table"
    rows = {t.names[i]: {face.names[j]: float(m.mapping[i, j]) for j in np.flatnonzero(m.mapping[i])}
            for i in range(len(t.names))}
    assert rows == {"jawOpen": {"aa": 1.0}, "eyeBlinkLeft": {"blinkLeft": 1.0}, "mouthSmileLeft": {"happy": 0.5},
                    "mouthSmileRight": {"happy": 0.5}, "cheekPuff": {}}
    assert m.unmatched_weights == ["cheekPuff"]
    anim = blendshapes.drive(face, t)
    happy = 0.5 * np.array([0, 1, 0.5, 0]) + 0.5 * np.array([0, 1, 0, 0])
    blink = np.array([0, 0, 1, 1])  # isBinary: on above 0.5
    want = np.repeat(BASE[None].astype(np.float64), 4, axis=0)
    want += np.array([0, 0.5, 1, 0.25])[:, None, None] * D[0]
    want += happy[:, None, None] * (0.5 * D[1] + 0.25 * D[2])
    want += blink[:, None, None] * D[2]
    np.testing.assert_allclose(anim.frames, want, atol=1e-6)
    info = anim.extras["weights"]
    assert info["route"] == "vrm-table" and info["counts"]["weights_unmatched"] == 1
    assert any("ARKit-to-VRM" in w for w in info["warnings"]) and any("binary" in w for w in info["warnings"])


def test_a_capture_weight_outside_the_table_still_drives_a_raw_morph_of_its_name():
    raw = ["mouthOpen", "tongueOut", "eyeClose_L"]
    face = face_of(v0([{"name": "A", "presetName": "a", "binds": [{"index": 0, "weight": 100}]}], raw=raw))
    t = track({"jawOpen": [0, 1], "tongueOut": [0, 0.5]})
    anim = blendshapes.drive(face, t)
    assert anim.extras["weights"]["route"] == "vrm-table"
    np.testing.assert_allclose(anim.frames[1], BASE + D[0] + 0.5 * D[1], atol=1e-6)


def test_one_sided_blinks_fall_back_on_blink():
    face = face_of(v1({"blink": {"morphTargetBinds": [{"index": 2}]}, "aa": {"morphTargetBinds": [{"index": 0}]}}))
    m = blendshapes.match_face(["eyeBlinkLeft", "eyeBlinkRight", "jawOpen"], face)
    blink = face.names.index("blink")
    assert m.route == "vrm-table" and m.mapping[:2, blink].tolist() == [0.5, 0.5]


def test_a_perfect_sync_avatar_is_driven_by_name():
    raw = ["jawOpen", "eyeBlinkLeft", "mouthSmileLeft"]
    groups = [{"name": "A", "presetName": "a", "binds": [{"index": 0, "weight": 100}]},
              {"name": "JawOpen", "presetName": "unknown", "binds": [{"index": 0, "weight": 50}]},
              {"name": "EyeBlinkLeft", "presetName": "unknown", "binds": [{"index": 2, "weight": 100}]},
              {"name": "MouthSmileLeft", "presetName": "unknown", "binds": [{"index": 1, "weight": 100}]}]
    face = face_of(v0(groups, raw=raw))
    t = track({"jawOpen": [0, 1], "eyeBlinkLeft": [0, 0.5], "mouthSmileLeft": [0, 0.25]})
    m = blendshapes.match_face(t.names, face)
    assert m.route == "names"
    assert [face.names[j] for j in np.flatnonzero(m.mapping.any(axis=0))] == ["JawOpen", "EyeBlinkLeft",
                                                                              "MouthSmileLeft"]
    anim = blendshapes.drive(face, t)
    np.testing.assert_allclose(anim.frames[1], BASE + 0.5 * D[0] + 0.5 * D[2] + 0.25 * D[1], atol=1e-6)
    assert anim.extras["weights"]["route"] == "names"


@pytest.mark.parametrize("mode,factor", [("block", 0.0), ("blend", 0.5)])
def test_vrm1_override_blink(mode, factor):
    preset = {"happy": {"overrideBlink": mode, "morphTargetBinds": [{"index": 1}]},
              "blinkLeft": {"morphTargetBinds": [{"index": 2}]}}
    face = face_of(v1(preset))
    t = track({"mouthSmileLeft": [0, 1], "mouthSmileRight": [0, 0], "eyeBlinkLeft": [1, 1]})
    anim = blendshapes.drive(face, t)
    np.testing.assert_allclose(anim.frames[0], BASE + D[2], atol=1e-6)  # no smile: the blink as captured
    np.testing.assert_allclose(anim.frames[1], BASE + 0.5 * D[1] + factor * D[2], atol=1e-6)


def test_a_binary_blink_is_fully_suppressed_by_any_override():
    preset = {"happy": {"overrideBlink": "blend", "morphTargetBinds": [{"index": 1}]},
              "blinkLeft": {"isBinary": True, "morphTargetBinds": [{"index": 2}]}}
    face = face_of(v1(preset))
    anim = blendshapes.drive(face, track({"mouthSmileLeft": [0, 0.1], "eyeBlinkLeft": [1, 1]}))
    np.testing.assert_allclose(anim.frames[0], BASE + D[2], atol=1e-6)
    np.testing.assert_allclose(anim.frames[1], BASE + 0.05 * D[1], atol=1e-6)


def test_a_parsed_capture_drives_the_avatar():
    face = face_of(v0([dict(g, binds=[dict(x) for x in g["binds"]]) for g in V0_GROUPS]))
    doc = {"fps": 10, "frames": [{"time": k / 10, "blendshapes": {"jawOpen": w, "eyeBlinkLeft": 0.0}}
                                 for k, w in enumerate([0.0, 0.5, 1.0])]}
    anim = blendshapes.drive(face, parse_weights(json.dumps(doc).encode(), "cap.json"))
    np.testing.assert_allclose(anim.frames - BASE, np.array([0, 0.5, 1])[:, None, None] * D[0], atol=1e-6)


# -- real files -------------------------------------------------------------------------------------------------

GODETTE_NAMES = ["HideHairBalls", "HdieEarRings", "HideBlush", "blink_left", "blink_right", "ah", "ih", "uu", "ee",
                 "oh", "look_up", "look_down", "look_left", "look_right", "angled_eyebrows"]
GODETTE_EXPRESSIONS = ["neutral", "aa", "ih", "ou", "ee", "oh", "blink", "happy", "angry", "sad", "relaxed", "lookUp",
                       "lookDown", "lookLeft", "lookRight", "blinkLeft", "blinkRight"]


@pytest.fixture(scope="module")
def godette(shared_data):
    return load_morph_face(shared_data / "real" / "Godette.vrm")


@pytest.mark.shared
def test_godette_gets_its_15_names_and_17_expressions(godette, shared_data):
    assert godette.names[:15] == GODETTE_NAMES
    assert [x.expression.name for x in godette.expressions] == GODETTE_EXPRESSIONS
    assert godette.extras["vrm"] == "0.x" and godette.extras["morph_targets"] == GODETTE_NAMES
    raw = {n: godette.deltas[k].astype(np.float64) for k, n in enumerate(GODETTE_NAMES)}
    by = {x.expression.name: godette.deltas[x.index] for x in godette.expressions}
    np.testing.assert_allclose(by["happy"], 0.5 * raw["oh"] + 0.25 * raw["look_up"], atol=1e-6)  # Joy: 50, 25
    np.testing.assert_allclose(by["blink"], raw["blink_left"] + raw["blink_right"], atol=1e-6)
    assert [godette.names[x.index] for x in godette.expressions if x.expression.binary] == ["blinkLeft", "blinkRight"]
    info = load_gltf((shared_data / "real" / "Godette.vrm").read_bytes(), shared_data / "real", name="Godette")
    assert info.extras["morph_targets"] == GODETTE_NAMES and info.extras["vrm_expressions"] == GODETTE_EXPRESSIONS


@pytest.mark.shared
def test_a_live_link_face_take_drives_godette_through_the_table(godette, shared_data):
    anim = blendshapes.drive(godette, read_weights(shared_data / "real" / "livelinkface_MySlate_3.csv"))
    info = anim.extras["weights"]
    # every table weight but eyeWideLeft/Right (Godette has no "surprised"); the capture's 27 others match nothing
    assert info["route"] == "vrm-table" and info["counts"]["weights_matched"] == len(blendshapes.ARKIT_TO_VRM) - 2
    assert {"EyeWideLeft", "EyeWideRight", "CheekPuff"} <= set(blendshapes.match_face(
        read_weights(shared_data / "real" / "livelinkface_MySlate_3.csv").names, godette).unmatched_weights)
    assert np.abs(anim.frames - godette.base).max() > 0


@pytest.mark.shared
def test_ready_player_me_is_still_driven_by_name(shared_data):
    face = load_morph_face(shared_data / "real" / "rpm_template_xr.glb")
    t = read_weights(shared_data / "real" / "livelinkface_MySlate_3.csv")
    m = blendshapes.match_face(t.names, face)
    assert m.route == "names" and not face.expressions
    jaw = t.names.index("JawOpen")
    assert [face.names[j] for j in np.flatnonzero(m.mapping[jaw])] == ["jawOpen"]
    assert np.array_equal(m.mapping, blendshapes.match_names(t.names, face.names).mapping)


@pytest.mark.shared
def test_convert_godette_with_a_capture_moves_the_mouth(shared_data, tmp_path):
    jaw = [0.0, 0.0, 0.5, 1.0, 0.0]
    cap = tmp_path / "cap.json"
    cap.write_text(json.dumps({"fps": 10, "frames": [
        {"time": k / 10, "blendshapes": {"jawOpen": w, "eyeBlinkLeft": 0.0}} for k, w in enumerate(jaw)]}))
    out = tmp_path / "x.svg"
    code = main(["convert", str(shared_data / "real" / "Godette.vrm"), "--weights", str(cap), "-o", str(out),
                 "--size", "256", "--frame-on", "Face", "-q"])
    assert code == 0
    ev = verify.evaluate(out.read_bytes())
    moved = np.abs(ev.xy - ev.xy[:1]).max(axis=(1, 2, 3))  # px, per frame, against the rest frame
    assert moved[2] > 1.5 and moved[3] > 3.0  # the mouth opens with jawOpen (aa)...
    assert abs(moved[3] - 2 * moved[2]) < 1.0  # ...linearly
    assert moved[1] < 1.0 and moved[4] < 1.0  # and rests where jawOpen is 0 (within the encoding's tolerance)
