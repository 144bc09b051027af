"""ARKit weight captures driving faces: the real Live Link Face take on the ICT head, glTF and OBJ-zip faces."""

import csv
import gzip
import io
import json
import re
import resource
import time
import zipfile
from functools import lru_cache
from pathlib import Path
from xml.sax.saxutils import unescape

import numpy as np
import pytest

from converter import blendshapes
from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.morphs import from_gltf, load_morph_face
from converter.formats.weights import read_weights

LLF = "real/livelinkface_MySlate_3.csv"
# ARKit's 52 names that ICT FaceKit's 27 shapes do not have (ICT has no eyeLook, squint, dimple, press, ...).
ICT_MISSING = {
    "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft", "EyeSquintLeft", "EyeLookDownRight",
    "EyeLookInRight", "EyeLookOutRight", "EyeLookUpRight", "EyeSquintRight", "MouthRight", "MouthLeft",
    "MouthDimpleLeft", "MouthDimpleRight", "MouthShrugLower", "MouthShrugUpper", "MouthPressLeft", "MouthPressRight",
    "MouthLowerDownLeft", "MouthLowerDownRight", "MouthUpperUpLeft", "MouthUpperUpRight", "CheekSquintLeft",
    "CheekSquintRight", "NoseSneerLeft", "NoseSneerRight", "TongueOut",
}


def obj_vertices(path) -> np.ndarray:
    """Vertex positions of a gzipped OBJ, read with numpy alone (independent of converter.formats.obj)."""
    lines = [ln for ln in gzip.decompress(path.read_bytes()).decode().splitlines() if ln.startswith("v ")]
    return np.loadtxt(io.StringIO("\n".join(ln[2:] for ln in lines)), usecols=(0, 1, 2))


@lru_cache(maxsize=1)
def ict_driven(folder: str, csv_path: str):
    face = load_morph_face(Path(folder))
    return face, blendshapes.drive(face, read_weights(csv_path))


@pytest.fixture(scope="module")
def driven(shared_data):
    return ict_driven(str(shared_data / "ict_facekit"), str(shared_data / LLF))


def test_llf_on_ict_matches_25_of_52_and_drives_every_shape(driven):
    face, anim = driven
    info = anim.extras["weights"]
    counts = info["counts"]
    assert len(face.names) == 27
    assert counts["weights_matched"] == 52 - len(ICT_MISSING) == 25
    assert counts["weights_unmatched"] == len(ICT_MISSING)
    assert counts["targets_driven"] == 27 and counts["targets_undriven"] == 0
    assert set(info["warnings"][0].split(": ", 1)[1].rstrip(".").split(", ")) == ICT_MISSING
    assert counts["head_rotation_applied"] == 0  # the take's head angles are all 0
    assert counts["eye_rotation_applied"] == 1  # ICT has eyeballs; the take's eye angles are not 0
    assert anim.n_frames == 328 and anim.fps == 60.0


def ict_names(csv_name: str, shapes: set[str]) -> list[str]:
    """The ICT shapes a Live Link Face column drives, spelled out by hand: EyeBlinkLeft -> eyeBlink_L, ..."""
    n = csv_name[0].lower() + csv_name[1:]
    if n in shapes:  # jawLeft, mouthClose
        return [n]
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if n.endswith(side):
            return [s for s in [n[: -len(side)] + suffix] if s in shapes]
    return [s for s in (n + "_L", n + "_R") if s in shapes]  # browInnerUp -> browInnerUp_L and _R


def test_llf_jaw_open_moves_the_jaw_by_its_shape_delta(driven, shared_data):
    _, anim = driven
    folder = shared_data / "ict_facekit" / "FaceXModel"
    neutral = obj_vertices(folder / "generic_neutral_mesh.obj.gz")
    jaw = obj_vertices(folder / "jawOpen.obj.gz") - neutral
    ids = np.flatnonzero(np.linalg.norm(jaw, axis=1) > 0.3)  # the jaw and chin
    ids = ids[ids < 9409]  # skin of the face (the eyeballs also turn with the eye angles)
    assert len(ids) > 200
    with open(shared_data / LLF, newline="") as fh:
        rows = list(csv.DictReader(fh))
    shapes = {p.name[: -len(".obj.gz")] for p in folder.glob("*.obj.gz")} - {"generic_neutral_mesh"}
    drives = {c: ict_names(c, shapes) for c in rows[0] if c not in ("Timecode", "BlendShapeCount")}
    used = sorted({s for v in drives.values() for s in v})
    deltas = {s: obj_vertices(folder / f"{s}.obj.gz")[ids] - neutral[ids] for s in used}
    w = np.array([float(r["JawOpen"]) for r in rows])
    for k in (int(np.argmax(w)), int(np.argmin(w)), len(w) // 2):
        others = sum(float(rows[k][c]) * deltas[s] for c, v in drives.items() for s in v if s != "jawOpen")
        moved = anim.frames[k, ids] - neutral[ids] - others
        np.testing.assert_allclose(moved, w[k] * jaw[ids], atol=2e-4)
    k = int(np.argmax(w))
    assert (
        np.linalg.norm(w[k] * jaw[ids], axis=1).max() > 0.5
    )  # the jaw really opens, by about half a centimetre or more


def test_llf_eye_yaw_turns_the_eyeballs_rigidly(driven, shared_data):
    face, anim = driven
    left, _ = blendshapes.eye_vertices(face)
    track = read_weights(shared_data / LLF)
    k = int(np.argmax(np.abs(track.eye_left[:, 0])))
    rest, moved = face.base[left].astype(np.float64), anim.frames[k, left].astype(np.float64)
    # Rigid: pairwise distances kept; the rotation angle between the centred point sets is the eye's angle.
    a, b = rest - rest.mean(0), moved - moved.mean(0)
    u, _, vt = np.linalg.svd(b.T @ a)
    r = u @ vt
    angle = np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))
    expected = blendshapes.rotations(track.eye_left[k:k + 1].astype(np.float64))[0]
    assert angle == pytest.approx(np.arccos(np.clip((np.trace(expected) - 1) / 2, -1, 1)), abs=1e-3)
    assert angle > 0.05


@pytest.mark.browser
@pytest.mark.slow
def test_llf_driven_ict_plays_in_chromium(driven, browser, artifacts):
    from converter.convert import convert_animation
    from converter.options import ConversionOptions
    from svgrender import chromium_frame

    _, anim = driven
    # The front of the face, every 4th triangle, 30 frames around the widest jaw opening: small enough for a test.
    w = read_weights_jaw(anim)
    k0 = max(0, int(np.argmax(w)) - 15)
    centre = anim.frames[0][anim.faces].mean(axis=1)
    keep = (centre[:, 2] > np.percentile(centre[:, 2], 80)) & (np.arange(anim.n_faces) % 4 == 0)
    used, inv = np.unique(anim.faces[keep], return_inverse=True)
    small = FaceAnimation(anim.frames[k0:k0 + 30][:, used], inv.reshape(-1, 3), anim.part_ids[keep], anim.parts,
                          anim.fps, "ict-llf")
    result = convert_animation(small, ConversionOptions(size=192))
    assert b"<svg" in result.data[:200]
    meta = json.loads(unescape(re.search(rb'<metadata id="facesvg">(.*?)</metadata>', result.data, re.S).group(1)
                               .decode()))
    assert meta["frames"] == 30 and meta["fps"] == pytest.approx(60.0)
    a = chromium_frame(browser, result.data, 0.0, 192, 192)
    b = chromium_frame(browser, result.data, 15 / 60, 192, 192)
    from PIL import Image

    Image.fromarray(np.concatenate([a, b], axis=1)).save(artifacts / "weights_llf_ict.png")
    # the face is drawn: every 4th triangle of its front, isolated, so all outline and drawn without the seam
    # stroke (7 % of the frame at 192 px; 10-11 % when every edge was stroked)
    assert (a[..., 3] > 127).mean() > 0.05
    assert np.abs(a.astype(int) - b.astype(int)).sum() > 0  # and it moves: the jaw opens


def read_weights_jaw(anim) -> np.ndarray:
    """Per-frame opening of the mouth in the driven frames: the chin's height below its rest height."""
    chin = int(np.argmin(anim.frames[0][:, 1] + 1e3 * (np.abs(anim.frames[0][:, 0]) > 1)))
    return anim.frames[0, chin, 1] - anim.frames[:, chin, 1]


def synthetic_llf(path, n_frames: int, names: list[str]) -> np.ndarray:
    """A Live Link Face CSV with n_frames at 60 fps, every weight a slow sine, a head sway; returns the weights."""
    k = np.arange(n_frames)
    w = 0.5 + 0.5 * np.sin(k[:, None] / 30.0 + np.arange(len(names))[None])
    head = np.stack([0.1 * np.sin(k / 50), 0.05 * np.sin(k / 70), 0.02 * np.sin(k / 90)], axis=1)
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["Timecode", "BlendShapeCount", *names, "HeadYaw", "HeadPitch", "HeadRoll"])
        for i in range(n_frames):
            s = i // 60
            tc = f"01:{s // 60:02d}:{s % 60:02d}:{i % 60:02d}.000"
            out.writerow([tc, len(names) + 3, *(f"{x:.6f}" for x in w[i]), *(f"{x:.6f}" for x in head[i])])
    return w


def test_head_yaw_rotates_the_face_rigidly_about_the_centre(tmp_path, sample_path):
    face = load_morph_face(sample_path)
    path = tmp_path / "take.csv"
    synthetic_llf(path, 120, ["JawOpen"])
    track = read_weights(path)
    anim = blendshapes.drive(face, track)
    assert anim.extras["weights"]["counts"]["head_rotation_applied"] == 1
    k = 100
    r = blendshapes.rotations(track.head[k:k + 1].astype(np.float64))[0]
    pivot = 0.5 * (face.base.min(0) + face.base.max(0))
    jaw = face.deltas[face.names.index("jawOpen")]
    expected = (face.base + track.values[k, 0] * jaw - pivot) @ r.T + pivot
    np.testing.assert_allclose(anim.frames[k], expected, atol=1e-4)
    yaw = track.head[k, 0]
    assert abs(yaw - 0.1 * np.sin(k / 50) * np.pi) < 1e-5  # Live Link Face angles: 1 unit = 180 degrees


@pytest.mark.slow
def test_a_4000_frame_capture_converts(tmp_path, shared_data):
    """Two minutes at 60 fps... of a 26,719-vertex head: the 3D stage only (the writers have their own benches)."""
    read = []
    face = load_morph_face(shared_data / "ict_facekit", progress=lambda stage, f: read.append(f))
    assert read == [(k + 1) / 27 for k in range(27)]  # a step per expression shape
    path = tmp_path / "long.csv"
    arkit = ["JawOpen", "EyeBlinkLeft", "EyeBlinkRight", "MouthSmileLeft", "MouthSmileRight", "BrowInnerUp"]
    w = synthetic_llf(path, 4000, arkit)
    t0, c0 = time.perf_counter(), time.process_time()
    anim = blendshapes.drive(face, read_weights(path))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"4000 frames x {len(face.base)} vertices: {seconds:.1f} s wall, {cpu:.1f} s CPU, peak RSS {rss:.0f} MB")
    assert anim.n_frames == 4000 and anim.frames.shape == (4000, len(face.base), 3)
    jaw = face.deltas[face.names.index("jawOpen")]
    ids = np.flatnonzero(np.linalg.norm(jaw, axis=1) > 0.3)[:50]
    # frame 0 has no head turn (sin 0): the jaw vertices sit at base + w * delta plus the other shapes there
    matched = ["jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L", "mouthSmile_R"]
    expected = face.base[ids] + sum(w[0, i] * face.deltas[face.names.index(n)][ids] for i, n in enumerate(matched))
    expected += w[0, 5] * (face.deltas[face.names.index("browInnerUp_L")][ids]
                           + face.deltas[face.names.index("browInnerUp_R")][ids])
    np.testing.assert_allclose(anim.frames[0, ids], expected, atol=1e-4)


def test_obj_zip_face_by_shape_name(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    faces = "f 1 2 3\nf 2 4 3\n"

    def obj(verts):
        return "".join(f"v {x} {y} {z}\n" for x, y, z in verts) + faces

    path = tmp_path / "shapes.zip"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("face/neutral.obj", obj(v))
        zf.writestr("face/jawOpen.obj", obj(v + [0, -1, 0]))
        zf.writestr("face/eyeBlink_L.obj", obj(v + [0, 0, 0.5]))
    calls = []
    face = load_morph_face(path, progress=lambda stage, f: calls.append((stage, f)))
    assert face.names == ["eyeBlink_L", "jawOpen"]
    assert calls == [("load", 0.5), ("load", 1.0)]  # a step per shape read
    csv_path = tmp_path / "w.json"
    names = ["jawOpen", "eyeBlinkLeft", "tongueOut"]
    csv_path.write_text(json.dumps({"exportFps": 10, "numFrames": 2, "facsNames": names,
                                    "weightMat": [[0.0, 1.0, 0.3], [0.5, 0.0, 0.3]]}))
    anim = blendshapes.drive(face, read_weights(csv_path))
    calls.clear()
    by_file = blendshapes.drive_file(path, csv_path, progress=lambda stage, f: calls.append((stage, f)))
    np.testing.assert_array_equal(by_file.frames, anim.frames)
    share = blendshapes.FACE_READ_SHARE  # reading the face, then driving it
    assert calls == [("load", share / 2), ("load", share), ("weights", 1.0)]
    np.testing.assert_allclose(anim.frames[0], v + [0, 0, 0.5], atol=1e-6)
    np.testing.assert_allclose(anim.frames[1], v + [0, -0.5, 0], atol=1e-6)
    assert anim.extras["weights"]["counts"]["weights_unmatched"] == 1


def test_gltf_targets_match_normalised_names(sample_path):
    face = from_gltf(sample_path.read_bytes(), sample_path.parent, "face")
    assert face.names[:3] == ["mouthSmile_L", "mouthSmile_R", "jawOpen"]
    m = blendshapes.match_names(["MouthSmileLeft", "ARKit_jawOpen", "blendShape1.eyeBlink.L", "eyeBlinkRight",
                                 "browInnerUp", "tongueOut"], face.names)
    assert m.unmatched_weights == ["tongueOut"]
    assert m.undriven_targets == ["mouthSmile_R", "browOuterUp_L", "browOuterUp_R"]
    # browInnerUp (ARKit, no side) drives both sides of a face that splits it
    assert m.mapping[4, face.names.index("browInnerUp_L")] == 1 and m.mapping[4, face.names.index("browInnerUp_R")] == 1


def test_gltf_deltas_in_world_space_on_every_mesh_rest_at_zero_weights():
    """Two meshes share `jawOpen`; one node scales by 2 and has default weights and a clip, one turns 90 degrees."""
    from converter.export.gltf_builder import ARRAY_BUFFER, GltfBuilder

    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    b = GltfBuilder()
    nodes = []
    for node_extra, names in (({"scale": [2, 2, 2], "weights": [0.5, 0.25]}, ["jawOpen", "smile"]),
                              ({"rotation": [0, np.sqrt(0.5), 0, np.sqrt(0.5)]}, ["jawOpen"])):
        pos = b.accessor(tri, minmax=True, target=ARRAY_BUFFER)
        targets = [{"POSITION": b.accessor(np.tile(np.float32([0, 0, 1 + k]), (3, 1)), target=ARRAY_BUFFER)}
                   for k in range(len(names))]
        mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "targets": targets}],
                                "extras": {"targetNames": names}})
        nodes.append(b.add("nodes", {"mesh": mesh, **node_extra}))
    b.add("scenes", {"nodes": nodes})
    t = b.accessor(np.float32([[0], [1]]), minmax=True)
    v = b.accessor(np.float32([[0.9], [0.1], [0.2], [0.3]]), "SCALAR")
    b.add("animations", {"samplers": [{"input": t, "output": v}],
                         "channels": [{"sampler": 0, "target": {"node": nodes[0], "path": "weights"}}]})
    face = from_gltf(b.glb(), Path("."), "two")
    assert face.names == ["jawOpen", "smile"]
    np.testing.assert_allclose(face.base[:3], 2 * tri, atol=1e-6)  # rest = weights 0, not the defaults or the clip
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # 90 degrees about +y
    np.testing.assert_allclose(face.base[3:], tri @ rot.T, atol=1e-6)
    np.testing.assert_allclose(face.deltas[0, :3], np.tile([0, 0, 2], (3, 1)), atol=1e-6)  # scaled by the node
    np.testing.assert_allclose(face.deltas[0, 3:], np.tile([1, 0, 0], (3, 1)), atol=1e-6)  # turned by the node
    np.testing.assert_allclose(face.deltas[1, :3], np.tile([0, 0, 4], (3, 1)), atol=1e-6)
    np.testing.assert_allclose(face.deltas[1, 3:], 0, atol=1e-6)  # the second mesh has no smile


def test_no_matching_name_is_one_sentence(tmp_path, sample_path):
    path = tmp_path / "w.json"
    path.write_text(json.dumps([{"time": 0, "blendshapes": {"foo": 1.0}}]))
    with pytest.raises(InputError, match="none of the 1 capture weights"):
        blendshapes.drive(load_morph_face(sample_path), read_weights(path))


def test_cli_convert_with_weights(tmp_path, sample_path):
    from converter.cli import main

    path = tmp_path / "w.json"
    path.write_text(json.dumps([{"time": k / 10, "blendshapes": {"jawOpen": k / 5}} for k in range(6)]))
    out = tmp_path / "o.svg"
    report = tmp_path / "r.json"
    assert main(["convert", str(sample_path), "--weights", str(path), "-o", str(out), "--report", str(report),
                 "--size", "128"]) == 0
    r = json.loads(report.read_text())
    assert r["counts"]["weights_matched"] == 1 and r["counts"]["targets_undriven"] == 8 and r["counts"]["frames"] == 6
    assert any("got no weight" in w for w in r["warnings"])


def test_verify_reloads_the_capture_from_the_metadata(tmp_path, sample_path):
    from converter.convert import convert
    from converter.options import ConversionOptions
    from converter.verify import verify_file

    path = tmp_path / "w.json"
    path.write_text(json.dumps([{"time": k / 10, "blendshapes": {"jawOpen": k / 5}} for k in range(6)]))
    result = convert(sample_path, ConversionOptions(size=128, weights=str(path)))
    (tmp_path / "o.svg").write_bytes(result.data)
    v = verify_file(tmp_path / "o.svg", sample_path)
    assert v.ok and v.frames == 6, v.summary()
