"""The puppet against three.js playing the same glTF, and against our 3D prerender over head angles.

The same morph weights (three.js: morphTargetInfluences by target name; the puppet: `puppet.set`) and the same
head turn (three.js: the scene turned about the puppet's pivot, R = Ry Rx Rz as blendshapes.drive turns it, which
is what the puppet's head parameters do) with the puppet's camera, compared by silhouette IoU and by SSIM of the
luminance (Gaussian window, skimage's structural_similarity), averaged over the union of the two silhouettes.

Colour: three.js draws flat Lambert in our light rig (tests/reference/player.js's restyle), relit from the posed
geometry; the puppet relights its rest normals turned by the head (morphs keep their rest normals). Where the glTF's
colours are plain (the generated face) SSIM is the flat puppet against three.js; where they are textured (the Ready
Player Me avatar: three.js's restyle draws it white, our loader keeps the colours) SSIM is the Gouraud puppet against
our prerender (converter/render.py, Gouraud in the same rig) at the same poses. The head angle sweep (0-50 degrees yaw,
then pitch) is the Gouraud puppet against our prerender; both relight the turned head, so SSIM holds with the angle as
the silhouette does (the measured figures are in bench/results/bench_puppet.md).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions, Report
from converter.puppet import from_track, puppet_of, resolve
from converter.puppet.take import frame_pose
from converter.writers import puppet as writer
from tests.conftest import ARTIFACTS, SHARED_DATA
from tests.puppet.faces import generated_face
from tests.reference import threejs

pytestmark = [pytest.mark.browser, pytest.mark.slow]

IOU_MIN = 0.98  # the targets, head angles within +-20 degrees
SSIM_MIN = 0.95
SIZE = 256
RPM = SHARED_DATA / "real" / "rpm_template_xr.glb"
LLF = SHARED_DATA / "real" / "livelinkface_MySlate_3.csv"
SWEEP = (0, 10, 20, 30, 40, 50)  # degrees of head yaw, then pitch
GROUP_RGB = ((0.85, 0.62, 0.5, 1.0), (0.95, 0.95, 0.92, 1.0), (0.95, 0.95, 0.92, 1.0))  # skin, left eye, right eye


@pytest.fixture(scope="module")
def player(browser):
    """The browser, once three.js is installed (skips locally without it, fails when CI is set)."""
    threejs.require()
    return browser


def face_glb() -> bytes:
    """tests/puppet/faces.py's generated face as a glTF: one primitive per part, its four named morph targets."""
    base, faces, group, targets = generated_face()
    group = np.asarray(group)
    b = GltfBuilder("tests")
    names = list(targets)
    prims = []
    for g, rgba in enumerate(GROUP_RGB):
        tri = faces[group == g]
        used = np.unique(tri)
        remap = np.full(len(base), -1)
        remap[used] = np.arange(len(used))
        prims.append({
            "attributes": {"POSITION": b.accessor(base[used].astype(np.float32), minmax=True, target=ARRAY_BUFFER)},
            "indices": b.accessor(remap[tri].astype(np.uint32).ravel(), target=ELEMENT_ARRAY_BUFFER),
            "targets": [{"POSITION": b.accessor(targets[n][used].astype(np.float32), minmax=True,
                                                target=ARRAY_BUFFER)} for n in names],
            "material": b.add("materials", {"pbrMetallicRoughness": {"baseColorFactor": list(rgba)}})})
    mesh = b.add("meshes", {"name": "face", "primitives": prims, "weights": [0.0] * len(names),
                            "extras": {"targetNames": names}})
    b.add("scenes", {"nodes": [b.add("nodes", {"name": "face", "mesh": mesh})]})
    return b.glb()


@pytest.fixture(scope="module")
def glb(tmp_path_factory) -> Path:
    """The generated face's glTF on disk."""
    path = tmp_path_factory.mktemp("puppet_threejs") / "face.glb"
    path.write_bytes(face_glb())
    return path


def save(name: str, *stacks: np.ndarray) -> None:
    """Rows of RGBA stacks over mid grey, one image in the artifacts folder."""
    ARTIFACTS.mkdir(exist_ok=True)
    rows = []
    for stack in stacks:
        row = np.concatenate(list(stack), axis=1).astype(float)
        a = row[..., 3:] / 255
        rows.append(row[..., :3] * a + 128 * (1 - a))
    Image.fromarray(np.concatenate(rows, axis=0).astype(np.uint8)).save(ARTIFACTS / f"puppet_threejs_{name}.png")


def compare(player, path: Path, poses: list[threejs.Pose], name: str, size: int = SIZE) -> tuple[list, list]:
    """(IoUs, SSIMs) of the puppet at each pose: IoU against three.js; SSIM against three.js where the glTF's
    colours are plain (no texture: both draw flat Lambert in our rig), else the Gouraud puppet against our
    prerender (three.js's restyle draws textured materials white, our loaders give their colours)."""
    face = load_morph_face(path)
    puppet = puppet_of(face, ConversionOptions(size=size))
    ours = threejs.puppet_posed(player, writer.write(puppet, ConversionOptions(), Report()), poses)
    ref, unknown = threejs.threejs_posed(player, path, puppet.camera, puppet.pivot, poses)
    assert not unknown, f"three.js has no morph target named {unknown}"
    assert ours.shape == ref.shape
    save(name, ours, ref)
    ious = [threejs.silhouette_iou(a, b) for a, b in zip(ours, ref)]
    if threejs.colours_comparable(path):
        ssims = [threejs.ssim_luma(a, b) for a, b in zip(ours, ref)]
    else:
        smooth = puppet_of(face, ConversionOptions(size=size, shading="gouraud"))
        shaded = threejs.puppet_posed(player, writer.write(smooth, ConversionOptions(), Report()), poses)
        pre = threejs.prerender_posed(face, smooth.camera, poses)
        save(name + "_prerender", shaded, pre)
        ssims = [threejs.ssim_luma(a, b) for a, b in zip(shaded, pre)]
    print(name, "IoU", [round(x, 4) for x in ious], "SSIM", [round(x, 4) for x in ssims])
    return ious, ssims


def test_generated_face_matches_threejs(player, glb):
    names = ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft", "browInnerUp"]
    poses = [threejs.Pose({}), threejs.Pose({"jawOpen": 1.0}), threejs.Pose({"jawOpen": 0.4, "mouthSmileLeft": 0.8}),
             threejs.Pose({"eyeBlinkLeft": 1.0, "browInnerUp": 1.0}),
             threejs.Pose(dict(zip(names, (0.6, 0.3, 0.5, 0.7))), (math.radians(15), math.radians(-10), 0.1)),
             threejs.Pose({"jawOpen": 0.8}, (math.radians(-20), math.radians(12), -0.15))]
    ious, ssims = compare(player, glb, poses, "generated")
    assert min(ious) >= IOU_MIN, ious
    assert min(ssims) >= SSIM_MIN, ssims  # the two turned poses too: both relight the turned head
    # the pose matters: the open jaw's three.js render fits the open puppet better than the closed one
    ours = threejs.puppet_posed(player, writer.write(puppet_of(load_morph_face(glb), ConversionOptions(size=SIZE)),
                                                     ConversionOptions(), Report()), poses[:2])
    assert threejs.silhouette_iou(ours[1], ours[0]) < ious[1]


def take_poses(path: Path, count: int) -> tuple[list[threejs.Pose], list[int]]:
    """count frames spread over a real take as poses by the RPM face's target names, and their indices."""
    take = from_track(read_weights(path))
    face = load_morph_face(RPM)
    puppet = puppet_of(face, ConversionOptions(size=SIZE))
    mapping = resolve(puppet, take.names)
    frames = threejs.spread_frames(take.n_frames, count)
    poses = []
    for k in frames:
        w, head, _ = frame_pose(take, k)
        mw = np.asarray(w, np.float64) @ mapping
        poses.append(threejs.Pose({p.name: float(v) for p, v in zip(puppet.morphs, mw) if v},
                                  tuple(float(a) for a in head) if head is not None else (0.0, 0.0, 0.0)))
    return poses, frames


@pytest.fixture(scope="module")
def rpm_take(player, shared_data) -> tuple[list[int], list[float], list[float]]:
    """(frames, IoUs, SSIMs) of the RPM avatar's puppet at 8 frames of the Live Link Face take, then the same frames
    with the head turned within +-20 degrees (the take's head columns are all zero)."""
    if not RPM.exists() or not LLF.exists():  # ../shared/data is there (shared_data): CI must have these too
        (pytest.fail if os.environ.get("CI") else pytest.skip)(
            "rpm_template_xr.glb or livelinkface_MySlate_3.csv missing from ../shared/data/real")
    poses, frames = take_poses(LLF, 8)
    turns = [(math.radians(y), math.radians(x), r) for y, x, r in
             ((15, 0, 0), (-20, 8, 0.1), (0, -15, 0), (10, 20, -0.15), (-12, -10, 0.2), (20, 0, 0), (0, 12, 0),
              (-5, 5, 0))]
    turned = [threejs.Pose(p.weights, t) for p, t in zip(poses, turns)]
    ious, ssims = compare(player, RPM, poses + turned, "rpm")
    return frames, ious, ssims


@pytest.mark.shared
def test_ready_player_me_take_matches_threejs(rpm_take):
    frames, ious, ssims = rpm_take
    assert min(ious) >= IOU_MIN, dict(zip(frames * 2, ious))  # weights only, and turned
    assert min(ssims[:len(frames)]) >= SSIM_MIN, dict(zip(frames, ssims))


@pytest.mark.shared
def test_ready_player_me_turned_take_keeps_ssim(rpm_take):
    frames, _, ssims = rpm_take
    assert min(ssims[len(frames):]) >= SSIM_MIN, dict(zip(frames, ssims[len(frames):]))


def sweep(browser, face, name: str) -> list[tuple[str, float, float, float]]:
    """The head angle sweep of a face's Gouraud puppet against our prerender; printed, saved as an artifact."""
    puppet = puppet_of(face, ConversionOptions(size=SIZE, shading="gouraud"))
    rows = threejs.angle_sweep(browser, face, writer.write(puppet, ConversionOptions(), Report()), puppet.camera,
                               SWEEP)
    for row in rows:
        axis, deg, iou, ssim, seen = row
        print(f"{name} {axis:<5} {deg:2.0f} deg  IoU {iou:.4f}  SSIM {ssim:.4f}  in view {seen:.2f}")
    return rows


@pytest.mark.shared
def test_ready_player_me_head_angle_sweep(browser, shared_data):
    if not RPM.exists():
        pytest.skip("rpm_template_xr.glb missing from ../shared/data/real")
    rows = sweep(browser, load_morph_face(RPM), "rpm")
    within = [r for r in rows if r[1] <= 20]
    assert min(r[2] for r in within) >= IOU_MIN, within
    assert min(r[3] for r in within) >= SSIM_MIN, within


def test_head_angle_sweep_against_the_prerender(browser, face):
    rows = sweep(browser, face, "generated")
    within = [r for r in rows if r[1] <= 20]
    assert min(r[2] for r in within) >= IOU_MIN, within
    assert min(r[3] for r in within) >= SSIM_MIN, within
    # the puppet relights the turned head as the prerender does: SSIM holds to 50 degrees (rest colours: it falls)
    assert min(r[3] for r in rows) >= SSIM_MIN, rows
