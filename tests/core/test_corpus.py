"""Every real input we hold, through every output kind with default options: a conversion either succeeds with
finite numbers or stops with one InputError, never a traceback.

The faces and captures of ../shared/data/real (captures drive the Ready Player Me avatar there as --weights), every
file of tests/data and tests/formats/data, the Xface FAP streams on the bundled sample, and the case a user hit: a
skinned multi-primitive avatar whose joint tracks scale a part to zero (or flatten it to a line) in some frames,
which stopped the default conversion with numpy's LinAlgError in the rigid planner."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SAMPLE, SHARED_DATA, SMALL_DATA, require_shared_data
from converter import formats
from converter.convert import convert_animation, load
from converter.errors import InputError
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.formats.weights import is_capture
from converter.options import ConversionOptions
from converter.outputs import OUTPUTS
from converter.verify import verify_animation
from tests.encode.test_degenerate import assert_finite_output

REAL = SHARED_DATA / "real"
RPM = REAL / "rpm_template_xr.glb"  # the face with ARKit morph targets the captures drive
END = 6  # frames converted of each input
SIZE = 96
SAMPLE_FDP = ROOT / "samples" / "face.fdp.json"
XFACE = SMALL_DATA / "mpeg4" / "xface"


def listing(*folders: Path) -> list[Path]:
    """Every file under the folders (recursively), sorted; none for a folder that is missing."""
    return sorted(p for f in folders if f.is_dir() for p in f.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts)


def ids(paths: list[Path], base: Path) -> list[str]:
    return [str(p.relative_to(base)) for p in paths]


def captures(paths: list[Path]) -> list[Path]:
    """The files among paths that are face captures (blendshape weights), by content."""
    return [p for p in paths if p.stat().st_size < 50_000_000 and is_capture(p.read_bytes())]


def convert_every_kind(path: Path, **options) -> dict[str, str]:
    """Load path (with options such as weights) and convert its first END frames to every output kind; the outcome
    per kind ('ok' or the InputError's text). Any other exception propagates and fails the test."""
    try:
        anim = load(path, ConversionOptions(**options))
    except InputError as exc:
        return {"load": str(exc)}
    outcomes = {}
    for kind in OUTPUTS:
        opts = ConversionOptions(to=kind, size=SIZE, end=min(END, anim.n_frames), **options)
        try:
            result = convert_animation(anim, opts)
        except InputError as exc:
            assert str(exc).strip()
            outcomes[kind] = str(exc)
            continue
        assert_finite_output(result.data, result.report, kind)
        outcomes[kind] = "ok"
    return outcomes


# --- ../shared/data/real -----------------------------------------------------------------------------------------
SHARED_FILES = listing(REAL)
SHARED_CAPTURES = captures(SHARED_FILES + listing(SMALL_DATA / "captures"))
MISSING = [pytest.param(None, id="shared-data-missing")]


@pytest.mark.shared
@pytest.mark.parametrize("path", SHARED_FILES or MISSING, ids=ids(SHARED_FILES, REAL) if SHARED_FILES else None)
def test_shared_file_through_every_output(path):
    require_shared_data()
    outcomes = convert_every_kind(path)
    if path.suffix.lower() in (".glb", ".gltf", ".vrm"):  # a face: the SVG and the player are written
        assert outcomes.get("svg") == "ok" and outcomes.get("player") == "ok", outcomes


@pytest.mark.shared
@pytest.mark.parametrize("capture", SHARED_CAPTURES or MISSING,
                         ids=ids(SHARED_CAPTURES, ROOT.parent) if SHARED_CAPTURES else None)
def test_capture_drives_the_avatar_through_every_output(capture):
    require_shared_data()
    convert_every_kind(RPM, weights=str(capture))


# --- tests/data and tests/formats/data ---------------------------------------------------------------------------
SMALL_FILES = listing(SMALL_DATA, ROOT / "tests" / "formats" / "data")


@pytest.mark.parametrize("path", SMALL_FILES, ids=ids(SMALL_FILES, ROOT / "tests"))
def test_small_data_file_through_every_output(path):
    outcomes = convert_every_kind(path)
    if path.suffix.lower() in (".glb", ".obj"):  # a face: at least the SVG is written
        assert outcomes.get("svg") == "ok", outcomes


FAPS = sorted(XFACE.glob("*.fap"))


@pytest.mark.slow
@pytest.mark.parametrize("fap", FAPS, ids=[p.stem for p in FAPS])
def test_xface_stream_drives_the_sample_through_every_output(fap):
    outcomes = convert_every_kind(SAMPLE, fap=str(fap), fdp=str(SAMPLE_FDP))
    assert all(outcomes[k] == "ok" for k in ("svg", "player", "fap2d")), outcomes


# --- the avatar a user converted: skinned, three primitives, a joint scaled to zero ---------------------------------
JOINTS = ("Hips", "Spine", "Neck", "Head", "LeftEye", "RightEye")
PARENT = {"Spine": "Hips", "Neck": "Spine", "Head": "Neck", "LeftEye": "Head", "RightEye": "Head"}
OFFSET = {"Hips": (0, -1.0, 0), "Spine": (0, 0.4, 0), "Neck": (0, 0.4, 0), "Head": (0, 0.2, 0),
          "LeftEye": (0.35, 0.3, 0.1), "RightEye": (-0.35, 0.3, 0.1)}


def grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid over [-1, 1]^2 at z = 0, counter-clockwise seen from +z."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    verts = np.stack([u, v, np.zeros_like(u)], -1).reshape(-1, 3)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).reshape(-1)
    return verts, np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])


def quaternion(axis, radians: float) -> np.ndarray:
    """x y z w of a rotation about axis."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    return np.r_[a * math.sin(radians / 2), math.cos(radians / 2)]


def skinned_avatar(frames: int = 24, hide: tuple[int, int] | None = (8, 13),
                   flatten: tuple[int, int] | None = None) -> bytes:
    """GLB of an avatar-creator-like head: one mesh of three skinned primitives (head skin, left and right eye) on a
    Hips > Spine > Neck > Head > eyes chain, joint rotation tracks (sway with jitter, gaze), the left eye's joint
    scaled to zero in frames hide (a part hidden by its joint) and the right eye's flattened to a line in frames
    flatten (scale y 0)."""
    b = GltfBuilder("tests")
    rest = {}
    for name in JOINTS:
        rest[name] = np.asarray(OFFSET[name], np.float64) + (rest[PARENT[name]] if name in PARENT else 0.0)
    node = {n: b.add("nodes", {"name": n, "translation": [float(x) for x in OFFSET[n]]}) for n in JOINTS}
    for child, parent in PARENT.items():
        b.doc["nodes"][node[parent]].setdefault("children", []).append(node[child])
    prims = []
    for label, joint, n, size in (("Head", "Head", 16, 0.8), ("EyeLeft", "LeftEye", 9, 0.18),
                                  ("EyeRight", "RightEye", 9, 0.18)):
        v, f = grid(n)
        pos = (v * size + rest[joint] + (0, 0, 0.0 if joint == "Head" else 0.02)).astype(np.float32)
        joints = np.zeros((len(v), 4), np.uint8)
        joints[:, 0] = JOINTS.index(joint)
        weights = np.zeros((len(v), 4), np.float32)
        weights[:, 0] = 1
        colour = [0.9, 0.9, 0.9, 1] if joint != "Head" else [0.8, 0.5, 0.4, 1]
        material = b.add("materials", {"name": f"Wolf3D_{label}", "pbrMetallicRoughness": {"baseColorFactor": colour}})
        prims.append({"attributes": {"POSITION": b.accessor(pos, minmax=True, target=ARRAY_BUFFER),
                                     "JOINTS_0": b.accessor(joints, target=ARRAY_BUFFER),
                                     "WEIGHTS_0": b.accessor(weights, target=ARRAY_BUFFER)},
                      "indices": b.accessor(f.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER),
                      "material": material})
    mesh = b.add("meshes", {"name": "Wolf3D_Avatar", "primitives": prims})
    inverse_bind = np.stack([np.eye(4)] * len(JOINTS))
    inverse_bind[:, :3, 3] = -np.stack([rest[n] for n in JOINTS])
    skin = b.add("skins", {"joints": [node[n] for n in JOINTS], "skeleton": node["Hips"], "inverseBindMatrices":
                           b.accessor(inverse_bind.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32), "MAT4")})
    b.add("scenes", {"nodes": [b.add("nodes", {"name": "Avatar", "mesh": mesh, "skin": skin}), node["Hips"]]})
    anim = b.doc["animations"] = [{"samplers": [], "channels": []}]
    times = b.accessor((np.arange(frames) / 25.0).astype(np.float32)[:, None], minmax=True)

    def track(joint: str, path: str, values) -> None:
        anim[0]["samplers"].append({"input": times, "output": b.accessor(np.asarray(values, np.float32)),
                                    "interpolation": "LINEAR"})
        anim[0]["channels"].append({"sampler": len(anim[0]["samplers"]) - 1,
                                    "target": {"node": node[joint], "path": path}})

    rng = np.random.default_rng(2)
    phase = np.arange(frames) / frames
    for joint, (axis, amplitude, shift) in {"Head": ((0, 1, 0.3), 0.35, 0), "Neck": ((1, 0, 0), 0.1, 1),
                                            "Spine": ((0, 0, 1), 0.05, 2), "LeftEye": ((0, 1, 0), 0.3, 3),
                                            "RightEye": ((0, 1, 0), 0.3, 3)}.items():
        track(joint, "rotation", [quaternion(axis, amplitude * math.sin(2 * math.pi * x + shift)
                                             + 0.003 * rng.standard_normal()) for x in phase])
    for joint, span, axes in (("LeftEye", hide, slice(None)), ("RightEye", flatten, slice(1, 2))):
        if span is not None:
            scale = np.ones((frames, 3))
            scale[span[0]:span[1], axes] = 0.0
            track(joint, "scale", scale)
    return b.glb()


@pytest.mark.parametrize("case", [dict(), dict(hide=None, flatten=(6, 11)), dict(flatten=(14, 18))],
                         ids=["joint-scaled-to-zero", "part-flattened-to-a-line", "both"])
def test_skinned_avatar_with_a_part_scaled_away_converts(tmp_path, case):
    path = tmp_path / "avatar.glb"
    path.write_bytes(skinned_avatar(**case))
    anim = formats.load(path)
    assert anim.n_faces == 2 * 15 * 15 + 2 * 2 * 8 * 8 and len(anim.parts) == 3
    eye = np.unique(anim.faces[np.flatnonzero(np.isin(anim.part_ids, [1]))])
    hidden = case.get("hide", (8, 13))
    if hidden is not None:  # the loader applied the zero scale: the eye is one point in those frames
        assert np.ptp(anim.frames[hidden[0], eye], axis=0).max() < 1e-6
    for kind in OUTPUTS:
        opts = ConversionOptions(to=kind, size=128)
        try:
            result = convert_animation(anim, opts)
        except InputError:
            assert kind not in ("svg", "player"), kind  # only kinds that need more (a FAP stream) may refuse
            continue
        assert_finite_output(result.data, result.report, kind)
        if OUTPUTS[kind].verify:
            check = verify_animation(result.data, anim)
            assert check.ok, check.summary()
