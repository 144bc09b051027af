"""Bad glTF input: every case gives exactly one InputError, never another exception."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from converter.errors import InputError
from converter.export.gltf_builder import ARRAY_BUFFER, GltfBuilder
from converter.formats import load
from converter.formats.gltf import load_gltf
from tests.formats.helpers import add_track, skinned_triangle, triangle_scene

HERE = Path(".")


def good() -> bytes:
    b, n = triangle_scene()
    add_track(b, n, "translation", [0, 1], [[0, 0, 0], [1, 0, 0]])
    return b.glb()


def with_doc(change) -> bytes:
    b, n = triangle_scene()
    change(b, n)
    return b.glb()


def raises(data: bytes, match: str) -> None:
    with pytest.raises(InputError, match=match):
        load_gltf(data, HERE, None, "bad")


def test_empty_file(tmp_path):
    raises(b"", "empty")
    (tmp_path / "empty.glb").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        load(tmp_path / "empty.glb")


@pytest.mark.parametrize("cut", [5, 19, 40, -30, -1])
def test_truncated_glb(cut):
    raises(good()[:cut], "truncated|garbled|malformed")


def test_garbled_glb_json():
    data = bytearray(good())
    data[20:30] = b"\xff" * 10
    raises(bytes(data), "garbled")


def test_wrong_glb_version():
    data = bytearray(good())
    data[4:8] = struct.pack("<I", 1)
    raises(bytes(data), "version 1")


def test_gltf_without_a_mesh():
    b = GltfBuilder()
    b.add("scenes", {"nodes": [b.add("nodes", {"name": "empty"})]})
    raises(b.glb(), "no mesh")


def test_unsupported_required_extension_is_named():
    raises(with_doc(lambda b, n: b.use_extension("KHR_draco_mesh_compression")), "KHR_draco_mesh_compression")


def skin_case(change=None, **kwargs) -> bytes:
    b, node, joints = skinned_triangle(**kwargs)
    if change is not None:
        change(b, node, joints)
    return b.glb()


def attrs(b, node):
    return b.doc["meshes"][b.doc["nodes"][node]["mesh"]]["primitives"][0]["attributes"]


@pytest.mark.parametrize("data,match", [
    (lambda: skin_case(joints=[[5, 0, 0, 0]] * 3), "vertex 0 of node body is weighted to joint 5, but its skin has 1"),
    (lambda: skin_case(lambda b, n, j: attrs(b, n).update(WEIGHTS_0=b.accessor(np.float32([[1, 0, 0, 0]] * 2)))),
     "JOINTS_0/WEIGHTS_0 of mesh 0 do not hold 4 values for each of its 3 vertices"),
    (lambda: skin_case(lambda b, n, j: attrs(b, n).update(JOINTS_0=b.accessor(np.float32([[0, 0]] * 3)))),
     "JOINTS_0 of mesh 0 is not unsigned bytes or shorts"),
    (lambda: skin_case(lambda b, n, j: attrs(b, n).pop("WEIGHTS_0")), "JOINTS_n without matching WEIGHTS_n"),
    (lambda: skin_case(lambda b, n, j: [attrs(b, n).pop(k) for k in ("JOINTS_0", "WEIGHTS_0")]),
     "node body has a skin but its mesh has no JOINTS_0/WEIGHTS_0"),
    (lambda: skin_case(lambda b, n, j: b.doc["skins"][0].update(joints=[])), "skin 0 has no joints"),
    (lambda: skin_case(lambda b, n, j: b.doc["skins"][0].update(joints=[99])), "node 99 does not exist"),
    (lambda: skin_case(lambda b, n, j: b.doc["nodes"][n].update(skin=3)), "skin 3 does not exist"),
    (lambda: skin_case(n_joints=2, inverse_bind=np.eye(4)[None]), "1 inverse bind matrices for 2 joints"),
    (lambda: skin_case(weights=[[-1, 0, 0, 0]] * 3), "negative or non-finite skin weights"),
])
def test_bad_skins_give_one_input_error(data, match):
    raises(data(), match)


def test_nan_positions():
    b, _ = triangle_scene(positions=np.float32([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]]))
    raises(b.glb(), "NaN or infinite")


def test_infinite_animation_value():
    def inf(b, n):
        add_track(b, n, "translation", [0, 1], [[0, 0, 0], [np.inf, 0, 0]])
    raises(with_doc(inf), "NaN or infinite")


def test_decreasing_key_times():
    raises(with_doc(lambda b, n: add_track(b, n, "scale", [1, 0], [[1, 1, 1], [2, 2, 2]])), "increasing")


def test_index_past_the_vertices():
    def bad_index(b, n):
        b.doc["accessors"][1]["byteOffset"] = 0
        b.bin[b.doc["bufferViews"][1]["byteOffset"]] = 9
    raises(with_doc(bad_index), "index past")


def test_accessor_reading_past_its_view():
    raises(with_doc(lambda b, n: b.doc["accessors"][0].update(count=1000)), "past the end")


def test_node_cycle():
    def cycle(b, n):
        b.doc["nodes"][n]["children"] = [n]
    raises(with_doc(cycle), "cycle")


def test_weights_track_width_mismatch():
    def bad(b, n):
        d = b.accessor(np.zeros((3, 3), np.float32), target=ARRAY_BUFFER)
        b.doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": d}]
        add_track(b, n, "weights", [0, 1], [0, 1, 0, 1])
    raises(with_doc(bad), "weights")


def test_too_long_animation():
    raises(with_doc(lambda b, n: add_track(b, n, "translation", [0, 1e7], [[0, 0, 0], [1, 0, 0]])), "too long")


def test_wrong_json_types_give_input_error():
    b, _ = triangle_scene()
    doc = json.loads(b.gltf(None)[0])
    doc["meshes"][0]["primitives"] = "nonsense"
    raises(json.dumps(doc).encode(), "malformed")
    doc["meshes"] = {"a": 1}
    raises(json.dumps(doc).encode(), "malformed|does not exist")


def test_garbled_base64_and_non_gltf_json():
    b, _ = triangle_scene()
    text = b.gltf(None)[0].replace(b";base64,", b";base64,!!")
    raises(text, "base64")
    raises(b'{"hello": 1}', "not a glTF")
    raises(b'[' * 100000, "garbled")


def test_random_byte_flips_of_the_sample_give_input_error_or_load(sample_path):
    rng = np.random.default_rng(2024)
    for path in (sample_path, sample_path.with_name("face_gltfpack.glb")):
        original = path.read_bytes()
        for _ in range(40):
            data = bytearray(original)
            for pos in rng.integers(0, len(data), rng.integers(1, 8)):
                data[pos] = int(rng.integers(0, 256))
            try:
                load_gltf(bytes(data), HERE, None, "fuzz")
            except InputError:
                pass
        # Flips concentrated in the JSON chunk exercise the structural checks.
        json_len = struct.unpack_from("<I", original, 12)[0]
        for _ in range(40):
            data = bytearray(original)
            for pos in rng.integers(20, 20 + json_len, rng.integers(1, 4)):
                data[pos] = int(rng.choice(list(b'0123456789{}[]",:-.e')))
            try:
                load_gltf(bytes(data), HERE, None, "fuzz")
            except InputError:
                pass


def test_huge_declared_counts_are_refused_without_allocating():
    def huge(b, n):
        b.doc["accessors"][0].pop("bufferView")
        b.doc["accessors"][0]["count"] = 10 ** 9
    raises(with_doc(huge), "invalid count")

    def huge_meshopt(b, n):
        b.doc["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": {
            "buffer": 0, "byteLength": 4, "byteStride": 12, "count": 10 ** 9, "mode": "ATTRIBUTES"}}
    raises(with_doc(huge_meshopt), "invalid size")
