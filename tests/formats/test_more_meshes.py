"""PLY meshes and frame zips, .npy vertex arrays with a template, and a named message for each unsupported format."""

import io
import json
import struct
import zipfile

import numpy as np
import pytest
import trimesh

from converter.errors import InputError
from converter.formats import load, sniff

V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], np.float32)
F = np.array([[0, 1, 2], [1, 3, 2]], np.int32)


def ply_bytes(v=V, colors=None, ascii=False) -> bytes:
    """A PLY written by trimesh (an exporter that is not ours)."""
    mesh = trimesh.Trimesh(vertices=v, faces=F, vertex_colors=colors, process=False)
    return mesh.export(file_type="ply", encoding="ascii" if ascii else "binary")


def test_ply_mesh_keeps_vertex_order_and_colours(tmp_path):
    # vertices deliberately unused-first / duplicated: process=False must keep them all, in order
    v = np.vstack([V, V[:1]])
    colors = np.array([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [255, 255, 0, 255], [9, 9, 9, 255]],
                      np.uint8)
    (tmp_path / "face.ply").write_bytes(ply_bytes(v, colors, ascii=True))
    a = load(tmp_path / "face.ply")
    assert a.n_frames == 1 and a.n_vertices == 5
    np.testing.assert_allclose(a.frames[0], v)
    np.testing.assert_array_equal(a.faces, F)
    np.testing.assert_allclose(a.vertex_colors[2], [0, 0, 1], atol=1e-6)


def test_zip_of_ply_frames_is_a_sequence(tmp_path):
    path = tmp_path / "seq.zip"
    with zipfile.ZipFile(path, "w") as zf:
        for k in (10, 2, 1):  # natural order: 1, 2, 10
            zf.writestr(f"frames/f{k}.ply", ply_bytes(V + [0, 0.1 * k, 0]))
    a = load(path, fps=25)
    assert a.n_frames == 3 and a.fps == 25
    np.testing.assert_allclose(a.frames[:, 0, 1], [0.1, 0.2, 1.0], atol=1e-6)


def test_npy_with_a_ply_template_by_cache_and_in_a_zip(tmp_path):
    t = np.arange(6)[:, None, None] * np.float32([0, 0.01, 0]) + V[None]
    (tmp_path / "face.ply").write_bytes(ply_bytes())
    np.save(tmp_path / "anim.npy", t.reshape(6, -1))  # VOCASET/FaceFormer store (T, V*3)
    a = load(tmp_path / "face.ply", fps=60, cache=tmp_path / "anim.npy")
    assert a.n_frames == 6 and a.fps == 60
    np.testing.assert_allclose(a.frames, t, atol=1e-6)
    path = tmp_path / "both.zip"
    buf = io.BytesIO()
    np.save(buf, t)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("template.ply", ply_bytes())
        zf.writestr("seq01.npy", buf.getvalue())
    b = load(path)
    np.testing.assert_allclose(b.frames, t, atol=1e-6)
    assert b.fps == 30.0  # .npy stores no rate: the default, unless --fps


def test_npy_with_an_obj_template(tmp_path):
    (tmp_path / "face.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V) + "f 1 2 3\nf 2 4 3\n")
    np.save(tmp_path / "a.npy", np.stack([V, V + 1]).astype(np.float64))
    a = load(tmp_path / "face.obj", cache=tmp_path / "a.npy")
    np.testing.assert_allclose(a.frames[1], V + 1, atol=1e-6)


@pytest.mark.parametrize("array,words", [
    (np.zeros((3, 5, 3)), ["5 points", "4 vertices"]),
    (np.zeros((3, 7)), ["shape (3, 7)", "(frames, 4, 3)", "(frames, 12)"]),
    (np.array([{"a": 1}], dtype=object), ["pickled"]),
    (np.array(["x"]), ["not numbers"]),
])
def test_bad_npy_arrays(tmp_path, array, words):
    (tmp_path / "face.ply").write_bytes(ply_bytes())
    np.save(tmp_path / "a.npy", array, allow_pickle=True)
    with pytest.raises(InputError) as err:
        load(tmp_path / "face.ply", cache=tmp_path / "a.npy")
    assert all(w in str(err.value) for w in words), str(err.value)


def test_ply_without_faces_or_truncated(tmp_path):
    (tmp_path / "p.ply").write_bytes(trimesh.PointCloud(V).export(file_type="ply"))
    with pytest.raises(InputError, match="points but no faces"):
        load(tmp_path / "p.ply")
    (tmp_path / "t.ply").write_bytes(ply_bytes()[:-20])
    with pytest.raises(InputError, match="t.ply"):
        load(tmp_path / "t.ply")


def glb(doc: dict) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    return struct.pack("<4sII", b"glTF", 2, 20 + len(text)) + struct.pack("<II", len(text), 0x4E4F534A) + text


def usdz() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        zf.writestr("scene.usdc", b"PXR-USDC" + b"\0" * 80)
    return buf.getvalue()


UNSUPPORTED = [
    ("face.fbx", b"Kaydara FBX Binary  \x00\x1a\x00" + b"\0" * 40, ["binary FBX", "Blender", "glTF"]),
    ("face.fbx", b"; FBX 7.4.0 project file\nFBXHeaderExtension:  {\n", ["ASCII FBX", "Blender", "glTF"]),
    ("face.usda", b"#usda 1.0\n(\n)\n", ["USD scene", "Blender", "glTF"]),
    ("face.usdc", b"PXR-USDC\x00\x00" + b"\0" * 40, ["USD scene", "glTF"]),
    ("face.usdz", usdz(), ["USDZ", "glTF"]),
    ("walk.bvh", b"HIERARCHY\nROOT Hips\n{\n", ["BVH", "no mesh", "rigged"]),
    ("face.abc", b"Ogawa\xff\x00\x01" + b"\0" * 40, ["Alembic", "OBJ"]),
    ("anim.npy", b"\x93NUMPY\x01\x00" + b"\0" * 40, ["NumPy vertex array", "--cache"]),
    ("take.csv", b"Timecode,BlendShapeCount,EyeBlinkLeft\n00:00:00:00.000,1,0.1\n",
     ["Live Link Face capture", "--weights"]),
    ("a2f.json", json.dumps({"exportFps": 30, "facsNames": ["jawOpen"], "weightMat": [[0.1]]}).encode(),
     ["Audio2Face", "--weights"]),
    ("arkit.json", json.dumps([{"time": 0, "blendshapes": {"jawOpen": 0.1}}]).encode(),
     ["ARKit blendshape weight capture", "--weights"]),
    ("other.json", json.dumps({"name": "not a model", "values": [1, 2]}).encode(), ["JSON but not a glTF", "asset"]),
    ("draco.glb", glb({"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_draco_mesh_compression"],
                       "extensionsRequired": ["KHR_draco_mesh_compression"]}),
     ["Draco", "KHR_draco_mesh_compression", "without Draco"]),
]


@pytest.mark.parametrize("filename,data,words", UNSUPPORTED, ids=[u[0] + str(i) for i, u in enumerate(UNSUPPORTED)])
def test_each_unsupported_format_is_named_with_what_to_do(tmp_path, filename, data, words):
    path = tmp_path / filename
    path.write_bytes(data)
    with pytest.raises(InputError) as err:
        load(path)
    msg = str(err.value)
    assert all(w in msg for w in words), msg
    assert msg.endswith(".") and "\n" not in msg


def test_sniff_still_knows_the_supported_kinds():
    assert sniff(ply_bytes()) == "ply"
    assert sniff(b'{"asset": {"version": "2.0"}}') == "gltf"
    with pytest.raises(InputError, match="not a glTF/GLB file"):
        sniff(b"\x00\x01garbage")
