"""Per-shape columns JSON (didimo's digital-human SDK): one list of values per blendshape, plus head and eye joints.

Layout (the SDK's DidimoAnimationJson, Newtonsoft-serialised; required fields marked *):
`{"source"*: "ARKit", "poses"*: {name: [one value per frame]}, "frameCount"*: N, "animationLength"*: seconds,
"fps": 60 (the SDK's default when absent), "timestamps": [seconds per frame], "skeleton": {"headPosition",
"headRotation", "leftEyeRotation", "rightEyeRotation": [[x, y, z] per frame]}}`. The SDK prefixes each pose name
with the source when it plays the file (`ARKit_jawOpen`); the names here are the file's, which facesvg matches
with or without that prefix.

Skeleton: the SDK turns each rotation triple into `Quaternion.Euler(x, y, z)` (Unity: degrees, x = pitch,
y = yaw, z = roll). So `headRotation`, `leftEyeRotation` and `rightEyeRotation` become the track's (yaw, pitch,
roll) = radians(y, x, z). Unity is left-handed; the signs are taken as written (the SDK documents no mirror).
`headPosition` is not used (a WeightTrack carries rotations only). Other skeleton keys are ignored.

Timing: `timestamps` when present (seconds), else frame k at k / fps; `frameCount` must equal every column's
length (and the timestamps'), else the file is truncated. The rate is `fps` as stated, or the timestamps'
spacing when `fps` is absent.
"""

from __future__ import annotations

import math
import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "columnar-json"
WHAT = "per-shape columns JSON"
SKELETON = {"head": "headRotation", "eye_left": "leftEyeRotation", "eye_right": "rightEyeRotation"}
_POSES = re.compile(rb'"poses"\s*:\s*\{')
_COUNT = re.compile(rb'"frameCount"\s*:')


def sniff(data: bytes) -> bool:
    """A JSON object with a "poses" object and a "frameCount"."""
    head = _util.head(data)
    return head[:1] == b"{" and bool(_POSES.search(head)) and bool(_COUNT.search(head))


def parse(data: bytes, name: str) -> WeightTrack:
    """The SDK's columns: one weight list per pose name, checked against frameCount; head and eye rotations."""
    doc = _util.json_doc(data, name, WHAT)
    if not isinstance(doc, dict) or not isinstance(doc.get("poses"), dict):
        raise InputError(f"{name}: a {WHAT} needs a \"poses\" object of {{name: [one value per frame]}}.")
    poses = doc["poses"]
    if not poses:
        raise InputError(f"{name}: \"poses\" is empty; the capture holds no blendshape weights.")
    count = doc.get("frameCount")
    if isinstance(count, bool) or not isinstance(count, int):
        raise InputError(f"{name}: frameCount is {str(count)[:30]!r}, not a whole number of frames.")
    _util.frame_count(count, name)
    names = list(poses)
    values = np.empty((count, len(names)), np.float64)
    for j, (pose, column) in enumerate(poses.items()):
        if not isinstance(column, list):
            raise InputError(f"{name}: pose {pose!r} is not a list of values.")
        if len(column) != count:
            raise InputError(f"{name}: pose {pose!r} has {len(column)} values but frameCount is {count}; the file "
                             "is truncated or edited.")
        try:
            values[:, j] = np.array(column, np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{name}: pose {pose!r} holds values that are not numbers.") from None
    _util.finite(values, name, "a pose weight")
    stated = _util.fps_value(doc["fps"], name) if doc.get("fps") is not None else None
    stamps = doc.get("timestamps")
    if stamps is not None:
        if not isinstance(stamps, list) or len(stamps) != count:
            got = len(stamps) if isinstance(stamps, list) else type(stamps).__name__
            raise InputError(f"{name}: timestamps has {got} entries but frameCount is {count}.")
        t = _util.increasing(np.array([_util.number(s, name, "a timestamp") for s in stamps]), name, "timestamps")
        fps = stated or _util.spacing_rate(t) or DEFAULT_FPS
    else:
        fps = stated or DEFAULT_FPS
        t = np.arange(count) / fps
    skeleton = doc.get("skeleton")
    angles = {k: _rotation(skeleton, key, count, name) if isinstance(skeleton, dict) else None
              for k, key in SKELETON.items()}
    return WeightTrack(names, t, values.astype(np.float32), float(fps), head=angles["head"],
                       eye_left=angles["eye_left"], eye_right=angles["eye_right"], source=NAME)


def _rotation(skeleton: dict, key: str, count: int, name: str) -> np.ndarray | None:
    """(T, 3) yaw, pitch, roll radians from the SDK's [[x, y, z] degrees] per frame, or None when absent."""
    rows = skeleton.get(key)
    if rows is None:
        return None
    if not isinstance(rows, list) or len(rows) != count:
        got = len(rows) if isinstance(rows, list) else type(rows).__name__
        raise InputError(f"{name}: skeleton {key} has {got} frames but frameCount is {count}.")
    try:
        xyz = np.array(rows, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: skeleton {key} holds values that are not numbers.") from None
    if xyz.shape != (count, 3):
        raise InputError(f"{name}: skeleton {key} must hold one [x, y, z] per frame.")
    _util.finite(xyz, name, f"skeleton {key}")
    return (xyz[:, [1, 0, 2]] * (math.pi / 180.0)).astype(np.float32)


LAYOUT = CaptureLayout(
    NAME, "didimo per-shape JSON", (".json",), sniff, parse,
    "didimo SDK's DidimoAnimationJson: source, poses {name: [values]}, frameCount, animationLength, fps, skeleton",
)
