"""Framing (issue 15, deliverable 7): --frame-on PART|NODE, the head of a full-body avatar, VRM 0.x facing -Z."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pytest

from converter import cli, formats
from converter.bundled import sample_path
from converter.camera import Camera
from converter.convert import convert_animation, extract_sheet, prepare
from converter.errors import InputError
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.extract import fit_camera
from converter.formats.gltf import load_gltf
from converter.options import ConversionOptions, Report

HERE = Path(__file__).parent
SIZE = 128


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Corners and 12 outward-facing (counter-clockwise from outside) triangles of an axis-aligned box."""
    lo, hi = np.asarray(lo, np.float32), np.asarray(hi, np.float32)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                       np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    p = corners[tris]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = np.einsum("fc,fc->f", normal, p.mean(axis=1) - corners.mean(axis=0)) > 0
    tris[~outward] = tris[~outward][:, ::-1]
    return corners, tris


def add_mesh(b: GltfBuilder, positions: np.ndarray, faces: np.ndarray, node_name: str, mesh_name: str,
             target_names: list[str] | None = None) -> int:
    """A mesh node (returned), not yet in a scene; target_names adds that many zero morph targets."""
    prim = {"attributes": {"POSITION": b.accessor(positions, minmax=True, target=ARRAY_BUFFER)},
            "indices": b.accessor(faces.astype(np.uint16).reshape(-1), target=ELEMENT_ARRAY_BUFFER)}
    mesh = {"name": mesh_name, "primitives": [prim]}
    if target_names:
        zero = b.accessor(np.zeros_like(positions), minmax=True, target=ARRAY_BUFFER)
        prim["targets"] = [{"POSITION": zero} for _ in target_names]
        mesh["extras"] = {"targetNames": target_names}
    return b.add("nodes", {"name": node_name, "mesh": b.add("meshes", mesh)})


def avatar(head_name: str = "Head", head_targets: list[str] | None = None) -> bytes:
    """A 2 m tall "Body" box with a 0.3 m head box on top, both under a root node "Avatar"."""
    b = GltfBuilder("tests")
    body = add_mesh(b, *box((-0.5, 0, -0.25), (0.5, 2.0, 0.25)), "Body", "BodyMesh")
    head = add_mesh(b, *box((-0.15, 2.0, -0.15), (0.15, 2.3, 0.15)), head_name, "HeadMesh", head_targets)
    root = b.add("nodes", {"name": "Avatar", "children": [body, head]})
    b.add("scenes", {"nodes": [root]})
    return b.glb()


def framed(data: bytes, **options) -> tuple:
    """(animation, sheet, report) of the SHEET stage with these options."""
    anim = load_gltf(data, HERE, None, "avatar")
    report = Report()
    sheet = extract_sheet(anim, ConversionOptions(size=SIZE, **options), report)
    return anim, sheet, report


def projected_extent(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min xy, max xy) in pixels of points seen by camera."""
    xy, _, _ = camera.project(points)
    return xy.reshape(-1, 2).min(axis=0), xy.reshape(-1, 2).max(axis=0)


def test_default_frames_the_head_of_a_full_body_avatar():
    anim, sheet, report = framed(avatar())
    head = anim.frames[0, 8:]  # the head box's corners follow the body's
    lo, hi = projected_extent(sheet.camera, head)
    assert (hi - lo).max() > 0.85 * SIZE  # the head fills the viewport
    assert lo.min() > -1 and hi.max() < SIZE + 1
    _, body_hi = projected_extent(sheet.camera, anim.frames[0, :8])
    assert body_hi[1] > 2 * SIZE  # the body's bottom is far below the view (pixel y grows downwards)
    assert any("framed the head (node 'Head')" in w for w in report.warnings)
    # the SVG's metadata carries that camera (what three.js replays), and the report says what was framed
    result = convert_animation(anim, ConversionOptions(size=SIZE))
    meta = json.loads(html.unescape(re.search(rb'<metadata id="facesvg">(.*?)</metadata>', result.data)[1].decode()))
    svg_camera = Camera.from_json(meta["camera"])
    assert np.allclose(svg_camera.view, sheet.camera.view) and np.allclose(svg_camera.projection,
                                                                           sheet.camera.projection)
    assert any("framed the head (node 'Head')" in w for w in result.report.warnings)


def test_default_finds_a_head_by_its_face_morph_targets():
    anim, sheet, report = framed(avatar("Neckless", ["jawOpen", "eyeBlinkLeft", "mouthSmileLeft"]))
    lo, hi = projected_extent(sheet.camera, anim.frames[0, 8:])
    assert (hi - lo).max() > 0.85 * SIZE
    assert any("framed the head (node 'Neckless')" in w for w in report.warnings)


def test_frame_on_body_frames_the_body_and_a_part_frames_the_part():
    anim, sheet, report = framed(avatar(), frame_on="body")  # names match case-insensitively
    lo, hi = projected_extent(sheet.camera, anim.frames[0, :8])
    assert (hi - lo)[1] > 0.85 * SIZE and lo.min() > -1 and hi.max() < SIZE + 1
    head_lo, _ = projected_extent(sheet.camera, anim.frames[0, 8:])
    assert head_lo[1] < 0  # the head is above the view
    assert any("framed 'body'" in w for w in report.warnings)
    whole = fit_camera(anim, SIZE, frame_on="Avatar")  # a parent node frames its children: everything
    everything = Camera.fit(anim.frames, size=SIZE)
    assert np.allclose(whole.view, everything.view) and np.allclose(whole.projection, everything.projection)


def test_frame_on_a_part_of_the_sample():
    sample = formats.load(sample_path())
    camera = fit_camera(sample, SIZE, frame_on="iris")
    named_iris = [i for i, p in enumerate(sample.parts) if p.name == "iris"]  # one part per eye's primitive
    iris = np.unique(sample.faces[np.isin(sample.part_ids, named_iris)])
    lo, hi = projected_extent(camera, sample.frames[:, iris])
    assert (hi - lo).max() > 0.85 * SIZE
    face_lo, face_hi = projected_extent(camera, sample.frames[0])
    assert (face_hi - face_lo).max() > 1.5 * SIZE  # the rest of the face overflows


def test_unknown_frame_on_is_one_input_error_listing_the_names():
    with pytest.raises(InputError) as err:
        framed(avatar(), frame_on="Tail")
    message = str(err.value)
    assert "'Tail'" in message and message.count(".") >= 1
    for name in ("skin", "Avatar", "Body", "BodyMesh", "Head", "HeadMesh"):
        assert name in message


def test_face_only_files_are_framed_as_before():
    b = GltfBuilder("tests")
    face = add_mesh(b, *box((-0.1, -0.12, -0.05), (0.1, 0.12, 0.05)), "face", "face")
    teeth = add_mesh(b, *box((-0.03, -0.06, 0.0), (0.03, -0.04, 0.04)), "teeth", "teeth",
                     ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft"])  # short, with face targets, but not on top
    b.add("scenes", {"nodes": [b.add("nodes", {"name": "head", "children": [face, teeth]})]})
    anim, sheet, report = framed(b.glb())
    plain = Camera.fit(anim.frames, size=SIZE)
    assert sheet.camera.view.tolist() == plain.view.tolist()
    assert sheet.camera.projection.tolist() == plain.projection.tolist()
    assert not any("framed" in w for w in report.warnings)
    sample = formats.load(sample_path())
    camera, plain = fit_camera(sample, SIZE), Camera.fit(sample.frames, size=SIZE)
    assert camera.view.tolist() == plain.view.tolist() and camera.projection.tolist() == plain.projection.tolist()


def facing_pair(vrm: dict | None) -> bytes:
    """Two triangles: "front" faces -Z (a VRM 0.x avatar's front), "back" faces +Z; extensions as given."""
    b = GltfBuilder("tests")
    minus_z = np.array([[2, 0, 0], [2, 1, 0], [3, 0, 0]], np.float32)
    plus_z = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    front = add_mesh(b, minus_z, np.array([[0, 1, 2]]), "front", "front")
    back = add_mesh(b, plus_z, np.array([[0, 1, 2]]), "back", "back")
    b.add("scenes", {"nodes": [front, back]})
    if vrm:
        b.doc["extensions"] = vrm
        b.doc.setdefault("extensionsUsed", []).extend(vrm)
    return b.glb()


@pytest.mark.parametrize("vrm, visible", [
    (None, [False, True]),
    ({"VRM": {"specVersion": "0.0"}}, [True, False]),  # VRM 0.x faces -Z: the camera turns round
    ({"VRMC_vrm": {"specVersion": "1.0"}}, [False, True]),  # VRM 1.0 faces +Z like glTF
])
def test_vrm_0x_avatars_are_seen_from_their_front(vrm, visible):
    anim, sheet, report = framed(facing_pair(vrm))
    assert sheet.visible[0].tolist() == visible
    assert any("VRM 0.x" in w for w in report.warnings) == (vrm is not None and "VRM" in vrm)


def test_info_lists_what_frame_on_accepts(tmp_path, capsys):
    path = tmp_path / "avatar.glb"
    path.write_bytes(avatar())
    assert cli.main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frame_on"] == ["skin", "Avatar", "Body", "BodyMesh", "Head", "HeadMesh"]


def test_frame_on_a_joint_frames_the_vertices_it_moves_most():
    b = GltfBuilder("tests")
    body = np.array([[0, 0, 0], [1, 0, 0], [0, 1.8, 0]], np.float32)
    head = np.array([[0, 1.8, 0], [0.2, 1.8, 0], [0, 2.0, 0]], np.float32)
    joints = np.zeros((6, 4), np.uint8)
    joints[3:, 0], joints[3:, 1] = 1, 0  # the head triangle: mostly the Head joint, a little the Hips
    weights = np.float32([[1, 0, 0, 0]] * 3 + [[0.7, 0.3, 0, 0]] * 3)
    attrs = {"POSITION": b.accessor(np.concatenate([body, head]), minmax=True, target=ARRAY_BUFFER),
             "JOINTS_0": b.accessor(joints, target=ARRAY_BUFFER), "WEIGHTS_0": b.accessor(weights, target=ARRAY_BUFFER)}
    mesh = b.add("meshes", {"name": "Character", "primitives": [{"attributes": attrs}]})
    head_joint = b.add("nodes", {"name": "mixamorig:Head"})
    hips = b.add("nodes", {"name": "mixamorig:Hips", "children": [head_joint]})
    node = b.add("nodes", {"name": "Character", "mesh": mesh, "skin": b.add("skins", {"joints": [hips, head_joint]})})
    b.add("scenes", {"nodes": [node, hips]})
    anim, sheet, report = framed(b.glb(), frame_on="mixamorig:head")
    lo, hi = projected_extent(sheet.camera, anim.frames[0, 3:])
    assert (hi - lo).max() > 0.85 * SIZE
    _, body_hi = projected_extent(sheet.camera, anim.frames[0, :3])
    assert body_hi[1] > 2 * SIZE
    hips_camera = fit_camera(anim, SIZE, frame_on="mixamorig:Hips")  # the Hips and its child Head: everything
    assert np.allclose(hips_camera.view, Camera.fit(anim.frames, size=SIZE).view)


def test_the_head_stays_framed_after_the_triangle_budget_drops_the_body():
    anim = load_gltf(avatar(), HERE, None, "avatar")
    options, report = ConversionOptions(size=SIZE, max_triangles=14), Report()
    simplified = prepare(anim, options, report)
    assert simplified.n_vertices < anim.n_vertices  # the budget dropped vertices the framing looked at
    sheet = extract_sheet(simplified, options, report)
    names = [node for node, *_ in simplified.extras["node_tree"]]
    kept_head = simplified.frames[0][simplified.extras["node_of_vertex"] == names.index("Head")]
    assert len(kept_head) >= 3
    lo, hi = projected_extent(sheet.camera, kept_head)
    assert (hi - lo).max() > 0.85 * SIZE
    assert any("framed the head (node 'Head')" in w for w in report.warnings)
