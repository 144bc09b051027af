"""NVIDIA Audio2Face blendshape export (JSON): ARKit weights, and the eye and jaw joints of newer exports.

Layout (what A2F's Blendshape Conversion "Export ... as .json" writes; the Audio2FaceExportData interface of
Babylon.js integrations types it the same way):
`{"exportFps", "trackPath", "numPoses", "numFrames", "facsNames": [K], "weightMat": [numFrames][K]}`, and from
A2F 2023 on also `"joints": [J]` (e.g. jaw, eye_L, eye_R), `"rotations": [numFrames][J][4]` quaternions with w
first, and `"translations": [numFrames][J][3]`.

Joints become the track's angles:
- `eye_L` / `eye_R` (A2F's rot_left_eye / rot_right_eye: the character's own left and right) -> `eye_left` /
  `eye_right` as (yaw, pitch, roll) radians. Axis convention: A2F runs in Omniverse (USD), Y up, right-handed,
  the character facing +Z, so +X is the character's left. That is the frame `converter.blendshapes` turns eyes
  in (yaw about +y, pitch about +x, roll about +z, R = Ry(yaw) Rx(pitch) Rz(roll)), so each quaternion's matrix
  is split into those three angles with no axis swap, and the stage rebuilds exactly the rotation A2F wrote.
  The real export this was checked on (a2f_charlie_bsweight.json) agrees: the jaw quaternion's x part rises
  with the jawOpen weight (r = 0.92), i.e. opening turns the chin from +Z down to -Y, which holds only when the
  face looks along +Z with Y up.
- `jaw` drives the `jawOpen` weight only when the file carries no jawOpen weight: its pitch (opening, about +x)
  over JAW_FULL_OPEN, clipped to 0..1. When `facsNames` has jawOpen, the jaw joint is ignored (the weight
  already opens the mouth; adding the bone's turn would open it twice).
- translations are checked (shape, finite) but not used: a WeightTrack carries rotations only, and A2F's eye
  joints do not translate (all zero in the real export); the jaw's slide is part of what jawOpen shows.
"""

from __future__ import annotations

import math

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util, reading
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

WHAT = "Audio2Face blendshape export"
# Jaw pitch that stands for jawOpen = 1, fitted on the real A2F 2023.2 export (800 frames with both the jaw joint and
# the jawOpen weight, r = 0.92): clip(pitch / 25 deg, 0, 1) gives the weight within 0.030 RMS (weights there average
# 0.077, peak 0.37; 20 deg gives 0.039 RMS, 32 deg 0.036).
JAW_FULL_OPEN = math.radians(25.0)
EYE_JOINTS = {"eye_left": "eye_L", "eye_right": "eye_R"}  # A2F's joint names -> the WeightTrack fields
JAW_JOINT = "jaw"


def sniff(data: bytes) -> bool:
    """True for JSON carrying Audio2Face's facsNames and weightMat keys."""
    head = _util.head(data)
    return head[:1] == b"{" and b'"facsNames"' in head and b'"weightMat"' in head


def parse(data: bytes, name: str = "audio2face.json") -> WeightTrack:
    """An Audio2Face export's bytes as a WeightTrack (weights 0..1, eye angles in radians)."""
    doc = _util.json_doc(data, name, WHAT)
    if not isinstance(doc, dict) or "facsNames" not in doc or "weightMat" not in doc:
        raise InputError(f"{name} is not an {WHAT}: it needs facsNames and weightMat.")
    return from_doc(doc, name)


def from_doc(doc: dict, name: str) -> WeightTrack:
    """A WeightTrack from an already parsed Audio2Face export object."""
    names = doc["facsNames"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise InputError(f"{name}: facsNames must be a non-empty list of blendshape names.")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(f"{name}: facsNames lists {dup!r} twice.")
    mat = reading.matrix(doc["weightMat"], len(names), name, "weightMat")
    fps = _util.fps_value(doc["exportFps"], name) if doc.get("exportFps") is not None else DEFAULT_FPS
    n = doc.get("numFrames")
    if n is not None and n != len(mat):
        raise InputError(f"{name}: numFrames is {n} but weightMat has {len(mat)} rows; the export is truncated.")
    poses = doc.get("numPoses")
    if poses is not None and poses != len(names):
        raise InputError(f"{name}: numPoses is {poses} but facsNames has {len(names)} names; the export is edited.")
    names = list(names)
    angles = _joint_angles(doc, len(mat), name)
    eyes = {key: angles.get(joint) for key, joint in EYE_JOINTS.items()}
    jaw = angles.get(JAW_JOINT)
    if jaw is not None and "jawOpen" not in names:
        names.append("jawOpen")
        mat = np.column_stack([mat, np.clip(jaw[:, 1] / JAW_FULL_OPEN, 0.0, 1.0)])
    times = np.arange(len(mat)) / fps
    return WeightTrack(names, times, mat.astype(np.float32), fps, eye_left=eyes["eye_left"],
                       eye_right=eyes["eye_right"], source=LAYOUT.name)


def _joint_angles(doc: dict, frames: int, name: str) -> dict[str, np.ndarray]:
    """{joint: (T, 3) float32 yaw, pitch, roll} from joints/rotations; {} when the export has no joints."""
    joints = doc.get("joints")
    if joints is None or joints == []:
        return {}
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise InputError(f"{name}: joints must be a list of joint names.")
    if "rotations" not in doc:
        raise InputError(f"{name} lists joints but has no rotations; the export is truncated.")
    rot = _per_joint(doc["rotations"], frames, len(joints), 4, name, "rotations")
    if "translations" in doc:
        _per_joint(doc["translations"], frames, len(joints), 3, name, "translations")
    norms = np.linalg.norm(rot, axis=2)
    if (norms < 1e-6).any():
        f, j = np.argwhere(norms < 1e-6)[0]
        raise InputError(f"{name}: rotations frame {f}, joint {joints[j]!r} is a zero quaternion.")
    rot = rot / norms[..., None]
    return {j: ypr_from_quaternions(rot[:, k]) for k, j in enumerate(joints)}


def _per_joint(rows, frames: int, joints: int, width: int, name: str, what: str) -> np.ndarray:
    """(T, J, width) float64 from [T][J][width] JSON lists, checked against the frame and joint counts."""
    if not isinstance(rows, list) or len(rows) != frames:
        got = len(rows) if isinstance(rows, list) else type(rows).__name__
        raise InputError(f"{name}: {what} has {got} frames but weightMat has {frames}; the export is truncated.")
    bad = next((k for k, frame in enumerate(rows) if not isinstance(frame, list) or len(frame) != joints), None)
    if bad is not None:
        raise InputError(f"{name}: {what} frame {bad} does not have one entry per joint ({joints}).")
    bad = next(((f, j) for f, frame in enumerate(rows) for j, e in enumerate(frame)
                if not isinstance(e, list) or len(e) != width), None)
    if bad is not None:
        raise InputError(f"{name}: {what} frame {bad[0]}, joint {bad[1]} is not a list of {width} numbers; every "
                         f"{what} entry needs {width}.")
    try:
        arr = np.array(rows, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: {what} holds values that are not numbers.") from None
    if not np.isfinite(arr).all():
        f, j, _ = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name}: {what} frame {f}, joint {j} holds NaN or infinite values.")
    return arr


def ypr_from_quaternions(q: np.ndarray) -> np.ndarray:
    """(T, 3) float32 yaw, pitch, roll with R = Ry(yaw) Rx(pitch) Rz(roll) from (T, 4) unit quaternions w, x, y, z."""
    w, x, y, z = (q[:, k] for k in range(4))
    # The matrix entries the angles need: column 2 (where +z turns to) and the first two of row 1.
    r02 = 2 * (x * z + w * y)
    r12 = 2 * (y * z - w * x)
    r22 = 1 - 2 * (x * x + y * y)
    r10 = 2 * (x * y + w * z)
    r11 = 1 - 2 * (x * x + z * z)
    yaw = np.arctan2(r02, r22)
    pitch = np.arcsin(np.clip(-r12, -1.0, 1.0))
    roll = np.arctan2(r10, r11)
    return np.stack([yaw, pitch, roll], axis=1).astype(np.float32)


LAYOUT = CaptureLayout(
    name="audio2face-json",
    label="Audio2Face blendshape export",
    extensions=(".json",),
    sniff=sniff,
    parse=parse,
    doc="NVIDIA Omniverse Audio2Face, Blendshape Conversion > export .json (facsNames/weightMat, joints/rotations)",
)
