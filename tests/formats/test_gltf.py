"""glTF loader: hierarchy, samplers against hand-computed values, morph targets, colours, buffers, meshopt."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from converter.errors import InputError
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder, encode_filter
from converter.formats import load
from converter.formats.gltf import _Document, load_gltf, parse_container
from tests.formats.helpers import TRI, add_track, srgb, triangle_scene

HERE = Path(".")


def z_quat(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(h), math.cos(h)]


def test_static_triangle_gives_one_frame_at_default_fps():
    b, _ = triangle_scene(material={"name": "Skin", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1, 1]}})
    a = load_gltf(b.glb(), HERE, None, "tri")
    assert a.n_frames == 1 and a.fps == 30.0
    np.testing.assert_array_equal(a.frames[0], TRI)
    assert a.faces.tolist() == [[0, 1, 2]]
    # baseColorFactor is linear (glTF 2.0); parts hold display (sRGB) colours.
    assert [(p.name, p.label) for p in a.parts] == [("skin", "node0/Skin")]
    np.testing.assert_allclose(a.parts[0].color, srgb([0.5, 0.25, 1.0]), atol=1e-6)
    assert a.vertex_colors is None


def test_rotation_track_is_slerped_under_a_translated_parent():
    b, child = triangle_scene()
    parent = b.add("nodes", {"translation": [10, 0, 0], "children": [child]})
    b.doc["scenes"][0]["nodes"] = [parent]
    # The second key is stored negated: slerp must still take the short 90 degree arc.
    add_track(b, child, "rotation", [0, 1], [z_quat(0), [-c for c in z_quat(90)]])
    a = load_gltf(b.glb(), HERE, 4.0, "rot")
    assert a.n_frames == 5 and a.fps == 4.0
    for k, deg in enumerate([0, 22.5, 45, 67.5, 90]):
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        np.testing.assert_allclose(a.frames[k, 1], [10 + c, s, 0], atol=1e-6)
        np.testing.assert_allclose(a.frames[k, 2], [10 - s, c, 0], atol=1e-6)
    assert a.extras["animated_nodes"] == [f"node{child}"]


def test_step_translation_holds_each_key_until_the_next():
    b, n = triangle_scene(node={"name": "head"})
    add_track(b, n, "translation", [0, 0.5, 1], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "STEP")
    a = load_gltf(b.glb(), HERE, 4.0, "step")
    assert a.frames[:, 0, 0].tolist() == [0, 0, 1, 1, 2]
    assert a.extras["animated_nodes"] == ["head"]


def test_cubicspline_translation_matches_hermite_by_hand():
    b, n = triangle_scene()
    # keys t=0 (v=0, out-tangent 1) and t=2 (in-tangent -3, v=1); x only. Values: in, value, out per key.
    add_track(b, n, "translation", [0, 2], [[9, 9, 9], [0, 0, 0], [1, 0, 0], [-3, 0, 0], [1, 0, 0], [9, 9, 9]],
              "CUBICSPLINE")
    a = load_gltf(b.glb(), HERE, 2.0, "cubic")
    # u = 0.25 at t = 0.5: h10 = 0.140625, h01 = 0.15625, h11 = -0.046875; dt = 2.
    # x = 0.140625*2*1 + 0.15625*1 + (-0.046875)*2*(-3) = 0.71875; at t = 1 (u = .5): 0.25 + 0.5 + 0.75 = 1.5;
    # at t = 1.5 (u = .75): 0.09375 + 0.84375 + 0.84375 = 1.78125.
    x = a.frames[:, 0, 0]
    np.testing.assert_allclose(x, [0, 0.71875, 1.5, 1.78125, 1.0], atol=1e-6)


def test_morph_weights_default_and_animated_linear_and_cubic():
    b = GltfBuilder()
    pos = b.accessor(TRI, minmax=True, target=ARRAY_BUFFER)
    d = b.accessor(np.tile(np.float32([0, 0, 2]), (3, 1)), target=ARRAY_BUFFER)
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "targets": [{"POSITION": d}]}],
                            "weights": [0.5], "extras": {"targetNames": ["jawOpen"]}})
    n = b.add("nodes", {"mesh": mesh})
    b.add("scenes", {"nodes": [n]})
    still = load_gltf(b.glb(), HERE, None, "m")
    np.testing.assert_allclose(still.frames[0, :, 2], 1.0)
    assert still.extras["morph_targets"] == ["jawOpen"]
    add_track(b, n, "weights", [0, 1], [0.0, 1.0])
    a = load_gltf(b.glb(), HERE, 4.0, "m")
    np.testing.assert_allclose(a.frames[:, 0, 2], [0, 0.5, 1, 1.5, 2], atol=1e-6)
    assert a.extras["morph_animated_nodes"] == [f"node{n}"]


def test_matrix_node_and_triangle_strip():
    b = GltfBuilder()
    quad = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    pos = b.accessor(quad, minmax=True, target=ARRAY_BUFFER)
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "mode": 5}]})
    m = np.eye(4)
    m[:3, :3] *= 2
    m[:3, 3] = [0, 5, 0]
    n = b.add("nodes", {"mesh": mesh, "matrix": m.T.reshape(-1).tolist()})  # column-major
    b.add("scenes", {"nodes": [n]})
    a = load_gltf(b.glb(), HERE, None, "strip")
    assert a.faces.tolist() == [[0, 1, 2], [1, 3, 2]]  # the odd triangle keeps counter-clockwise winding
    np.testing.assert_allclose(a.frames[0], quad * 2 + [0, 5, 0])


def test_sparse_accessors_on_positions_and_targets():
    b = GltfBuilder()
    base = b.view(TRI.tobytes(), stride=12, target=ARRAY_BUFFER)
    idx = b.view(np.uint16([2]).tobytes())
    val = b.view(np.float32([[0, 3, 0]]).tobytes())
    pos = b.add("accessors", {"bufferView": base, "componentType": 5126, "count": 3, "type": "VEC3",
                              "sparse": {"count": 1, "indices": {"bufferView": idx, "componentType": 5123},
                                         "values": {"bufferView": val}}})
    tgt = b.sparse_accessor(3, np.uint8([0]), np.float32([[0, 0, -4]]))
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "targets": [{"POSITION": tgt}]}],
                            "weights": [0.25]})
    b.add("scenes", {"nodes": [b.add("nodes", {"mesh": mesh})]})
    a = load_gltf(b.glb(), HERE, None, "sparse")
    np.testing.assert_allclose(a.frames[0], [[0, 0, -1], [1, 0, 0], [0, 3, 0]])


@pytest.mark.parametrize("colors, expected", [
    (np.uint8([[255, 128, 0, 255]] * 3), [1, 128 / 255, 0]),
    (np.uint16([[0, 65535, 32768]] * 3), [0, 1, 32768 / 65535]),
    (np.float32([[0.25, 0.5, 0.75, 1.0]] * 3), [0.25, 0.5, 0.75]),
])
def test_vertex_colours_float_and_normalized(colors, expected):
    b = GltfBuilder()
    c = b.accessor(colors, normalized=colors.dtype != np.float32, target=ARRAY_BUFFER)
    triangle_scene(b, extra_prim={"attributes": {"POSITION": b.accessor(TRI, target=ARRAY_BUFFER), "COLOR_0": c}})
    a = load_gltf(b.glb(), HERE, None, "colors")
    # COLOR_0 is linear; with no baseColorFactor the spec's white factor applies (not the part's default colour).
    assert a.parts[0].color == (1.0, 1.0, 1.0)
    np.testing.assert_allclose(a.vertex_colors, np.tile(srgb(expected), (3, 1)), atol=1e-6)


def test_parts_from_material_mesh_and_node_names():
    b = GltfBuilder()
    names = [("EyeSclera", None, "eye"), ("Iris_L", None, "iris"), ("UpperTeeth", None, "teeth"),
             ("Tongue", None, "mouth"), ("Eyelashes", None, "lashes"), (None, "Head", "skin"), (None, "gums", "mouth")]
    for k, (mat, mesh_name, _) in enumerate(names):
        material = {"name": mat, "pbrMetallicRoughness": {"baseColorFactor": [k / 10, 0, 0, 1]}} if mat else None
        triangle_scene(b, positions=TRI + k, material=material, mesh_name=mesh_name or "m")
    b.doc["scenes"] = [{"nodes": list(range(len(names)))}]
    a = load_gltf(b.glb(), HERE, None, "parts")
    assert [a.parts[i].name for i in a.part_ids] == [n for _, _, n in names]
    np.testing.assert_allclose(a.parts[a.part_ids[1]].color, srgb([0.1, 0.0, 0.0]), atol=1e-6)
    assert len(a.parts) == len(names)  # one part per primitive, labelled node/material (or mesh)
    assert a.parts[a.part_ids[1]].label == "node1/Iris_L" and a.parts[a.part_ids[5]].label == "node5/Head"


def test_external_buffer_and_refusal_of_paths_outside(tmp_path):
    b, _ = triangle_scene()
    text, binary = b.gltf("mesh%20data.bin")
    (tmp_path / "face.gltf").write_bytes(text)
    (tmp_path / "mesh data.bin").write_bytes(binary)
    a = load(tmp_path / "face.gltf")
    np.testing.assert_array_equal(a.frames[0], TRI)
    inner = tmp_path / "inner"
    inner.mkdir()
    doc = json.loads(text)
    doc["buffers"][0]["uri"] = "../mesh%20data.bin"
    (inner / "escape.gltf").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="outside"):
        load(inner / "escape.gltf")
    doc["buffers"][0]["uri"] = "missing.bin"
    (inner / "missing.gltf").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="missing"):
        load(inner / "missing.gltf")


def test_embedded_data_uri():
    b, _ = triangle_scene()
    text, _ = b.gltf(None)
    assert b"data:application/octet-stream;base64," in text
    np.testing.assert_array_equal(load_gltf(text, HERE, None, "e").frames[0], TRI)


def test_source_keyframe_rate_sets_default_fps():
    b, n = triangle_scene()
    add_track(b, n, "translation", np.arange(25) / 24, np.zeros((25, 3)))
    a = load_gltf(b.glb(), HERE, None, "rate")
    assert a.fps == 24.0 and a.n_frames == 25 and a.extras["source_fps"] == 24.0


def rotate_min_first(f: np.ndarray) -> np.ndarray:
    shift = f.argmin(1)
    return np.take_along_axis(f, (shift[:, None] + np.arange(3)) % 3, 1)


def _float_and_packed(quantized: bool) -> bytes:
    """The same animated two-triangle scene, as floats or gltfpack-style (quantized + meshopt)."""
    rng = np.random.default_rng(7)
    v = rng.uniform(-3, 3, (40, 3)).astype(np.float32)
    f = rng.integers(0, 40, (30, 3)).astype(np.uint16)
    delta = rng.uniform(-0.5, 0.5, (40, 3)).astype(np.float32)
    b = GltfBuilder()
    node: dict = {"name": "face"}
    if quantized:
        b.use_extension("KHR_mesh_quantization")
        lo, step = v.min(0), float((v.max(0) - v.min(0)).max()) / 16383
        q = np.zeros((40, 4), np.uint16)
        q[:, :3] = np.round((v - lo) / step)
        dq = np.zeros((40, 4), np.int16)
        dq[:, :3] = np.round(delta / step)
        pos = b.accessor(q, "VEC3", target=ARRAY_BUFFER, meshopt="ATTRIBUTES")
        tgt = b.accessor(dq, "VEC3", target=ARRAY_BUFFER, meshopt="ATTRIBUTES")
        ind = b.accessor(f.reshape(-1), target=ELEMENT_ARRAY_BUFFER, meshopt="TRIANGLES")
        node.update(translation=lo.tolist(), scale=[step] * 3)
    else:
        pos = b.accessor(v, target=ARRAY_BUFFER)
        tgt = b.accessor(delta, target=ARRAY_BUFFER)
        ind = b.accessor(f.reshape(-1), target=ELEMENT_ARRAY_BUFFER)
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "indices": ind,
                                            "targets": [{"POSITION": tgt}]}]})
    child = b.add("nodes", {**node, "mesh": mesh})
    head = b.add("nodes", {"name": "head", "children": [child]})
    b.add("scenes", {"nodes": [head]})
    times = np.arange(31, dtype=np.float32)[:, None] / 30
    rot = np.array([z_quat(30 * math.sin(k / 5)) for k in range(31)], np.float32)
    weights = (0.5 + 0.5 * np.sin(np.arange(31) / 4)).astype(np.float32)
    mo = "ATTRIBUTES" if quantized else None
    t = b.accessor(times, minmax=True, meshopt=mo)
    if quantized:
        r = b.accessor(encode_filter("quat", rot, 12), "VEC4", normalized=True, meshopt=mo, filter="QUATERNION")
        wq = np.round(weights * 255).astype(np.uint8)
        w = b.view(np.c_[wq, np.zeros((31, 3), np.uint8)].tobytes(), stride=4, meshopt=mo, count=31)
        w = b.add("accessors", {"bufferView": w, "componentType": 5121, "normalized": True, "count": 31,
                                "type": "SCALAR"})
        b.doc["bufferViews"][b.doc["accessors"][w]["bufferView"]]["byteStride"] = 4
    else:
        r = b.accessor(rot)
        w = b.accessor(weights[:, None])
    b.add("animations", {"samplers": [{"input": t, "output": r}, {"input": t, "output": w}], "channels": [
        {"sampler": 0, "target": {"node": head, "path": "rotation"}},
        {"sampler": 1, "target": {"node": child, "path": "weights"}}]})
    return b.glb()


def test_meshopt_compressed_quantized_gltf_matches_float_version():
    packed, plain = _float_and_packed(True), _float_and_packed(False)
    doc, _ = parse_container(packed)
    assert doc["extensionsRequired"] == ["KHR_mesh_quantization", "EXT_meshopt_compression"]
    modes = {bv["extensions"]["EXT_meshopt_compression"]["mode"] for bv in doc["bufferViews"]}
    assert modes == {"ATTRIBUTES", "TRIANGLES"}
    a, b = load_gltf(packed, HERE, None, "q"), load_gltf(plain, HERE, None, "f")
    assert a.n_frames == b.n_frames == 31 and a.fps == 30.0
    # The index codec may rotate a triangle's corners (keeping its winding).
    np.testing.assert_array_equal(rotate_min_first(a.faces), rotate_min_first(b.faces))
    # 14-bit positions over 6 units, 8-bit weights, 12-bit quaternions.
    np.testing.assert_allclose(a.frames, b.frames, atol=0.01)
    assert np.abs(a.frames - b.frames).max() > 0  # really quantized


def test_meshopt_octahedral_and_exponential_filters_decode():
    rng = np.random.default_rng(3)
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    floats = rng.uniform(-100, 100, (50, 3)).astype(np.float32)
    b = GltfBuilder()
    oct_view = b.view(encode_filter("oct", np.c_[normals, np.ones(50)], 8).tobytes(), stride=4,
                      meshopt="ATTRIBUTES", count=50, filter="OCTAHEDRAL")
    exp_view = b.view(encode_filter("exp", floats, 15).tobytes(), stride=12, meshopt="ATTRIBUTES", count=50,
                      filter="EXPONENTIAL")
    oct_acc = b.add("accessors", {"bufferView": oct_view, "componentType": 5120, "normalized": True, "count": 50,
                                  "type": "VEC4"})
    exp_acc = b.add("accessors", {"bufferView": exp_view, "componentType": 5126, "count": 50, "type": "VEC3"})
    doc, chunk = parse_container(b.glb())
    d = _Document(doc, chunk, HERE, "filters")
    np.testing.assert_allclose(d.accessor(oct_acc)[:, :3], normals, atol=0.02)
    np.testing.assert_allclose(d.accessor(exp_acc), floats, rtol=1e-3, atol=1e-2)


def test_ignorable_required_extension_loads():
    b, _ = triangle_scene()
    b.use_extension("KHR_texture_transform")
    b.use_extension("KHR_materials_unlit")
    assert load_gltf(b.glb(), HERE, None, "x").n_faces == 1


def test_primitives_sharing_one_vertex_buffer_keep_only_their_vertices():
    b = GltfBuilder()
    quad = np.float32([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5]])
    pos = b.accessor(quad, target=ARRAY_BUFFER)
    prims = []
    for tri, mat in (([0, 1, 2], "Skin"), ([0, 2, 3], "Teeth")):
        ind = b.accessor(np.uint16(tri), target=ELEMENT_ARRAY_BUFFER)
        prims.append({"attributes": {"POSITION": pos}, "indices": ind, "material": b.add("materials", {"name": mat})})
    b.add("scenes", {"nodes": [b.add("nodes", {"mesh": b.add("meshes", {"primitives": prims})})]})
    a = load_gltf(b.glb(), HERE, None, "shared")
    assert a.n_vertices == 6 and a.faces.tolist() == [[0, 1, 2], [3, 4, 5]]
    np.testing.assert_array_equal(a.frames[0, 3:], quad[[0, 2, 3]])
    assert [a.parts[i].name for i in a.part_ids] == ["skin", "teeth"]


@pytest.mark.parametrize("packed", ["gltfpack_cc.glb", "gltfpack_vpf.glb"])
def test_real_gltfpack_output_matches_its_float_input(packed):
    """Files written by the real gltfpack 1.3.0 (-cc: meshopt + every filter, quantized; see gltfpack_input.py)."""
    from scipy.spatial import cKDTree

    from tests.formats.gltfpack_input import scene

    data = (Path(__file__).parent / "data" / packed).read_bytes()
    doc, _ = parse_container(data)
    filters = {bv["extensions"]["EXT_meshopt_compression"].get("filter") for bv in doc["bufferViews"]
               if "extensions" in bv}
    assert {"QUATERNION", "EXPONENTIAL", "OCTAHEDRAL"} <= filters
    # gltfpack resamples animation at 30 Hz (its -af default): that rate becomes the default fps.
    assert load_gltf(data, HERE, None, "packed").fps == 30.0
    a, ref = load_gltf(data, HERE, 24.0, "packed"), load_gltf(scene(), HERE, None, "float")
    assert (a.n_frames, a.fps, a.n_faces, a.n_vertices) == (ref.n_frames, ref.fps, ref.n_faces, ref.n_vertices) == (
        25, 24.0, 242, 144)
    assert a.extras["morph_targets"] == ["smile", "jaw"] and a.extras["animated_nodes"] == ["face", "head"]
    assert [p.name for p in a.parts] == ["skin"] and np.allclose(a.parts[0].color, srgb([0.8, 0.6, 0.5]))
    # gltfpack may reorder vertices: match each frame's points by nearest neighbour.
    for k in range(0, 25, 4):
        dist, _ = cKDTree(ref.frames[k]).query(a.frames[k])
        assert dist.max() < 0.02, k
    assert np.ptp(a.frames[:, :, 1], axis=0).max() > 0.5  # it really moves


def test_float32_key_times_do_not_lose_the_last_frame():
    b, n = triangle_scene()
    add_track(b, n, "translation", np.arange(330) / 30, np.zeros((330, 3)))
    a = load_gltf(b.glb(), HERE, None, "long")
    assert (a.n_frames, a.fps) == (330, 30.0)


def test_quantized_normalized_positions_are_dequantized_by_the_node():
    b = GltfBuilder()
    b.use_extension("KHR_mesh_quantization")
    q = np.zeros((3, 4), np.int16)
    q[:, :3] = [[0, 0, 0], [32767, 0, 0], [0, -32767, 16384]]
    pos = b.accessor(q, "VEC3", normalized=True, minmax=True, target=ARRAY_BUFFER)
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}}]})
    b.add("scenes", {"nodes": [b.add("nodes", {"mesh": mesh, "scale": [4, 4, 4], "translation": [1, 0, 0]})]})
    a = load_gltf(b.glb(), HERE, None, "q")
    np.testing.assert_allclose(a.frames[0], [[1, 0, 0], [5, 0, 0], [1, -4, 4 * 16384 / 32767]], atol=1e-6)
