"""iFacialMocap (iOS) frames as text: the app's UDP datagrams, one frame per line when recorded to a file.

Layout of a frame (iFacialMocap's developer page, "for developer"; the real frames checked are the test strings of
korewaChino/rust-ifacialmocap): `|`-separated items,
- `<name>-<int>`: an ARKit weight times 100 (0..100), names with `_L`/`_R` sides (`eyeBlink_L`, `jawOpen`);
- `=head#rx,ry,rz,tx,ty,tz`: the head's rotation (degrees) and position; the `=` ends the weights;
- `rightEye#x,y,z` and `leftEye#x,y,z`: each eye's rotation in degrees;
- anything else (keys facesvg does not know, e.g. `hapihapi-0`, empty or bare trailing fields) is skipped.

Angles: x, y, z are pitch, yaw, roll, the convention Face Cap uses (Faceit hands iFacialMocap's head rotation to
its Face Cap importer unchanged; in the real frames both eyes share x, their pitch, while y differs in sign
between the eyes, their vergence). So, as in `facecap`, the head is (yaw, pitch, roll) = -radians(ry, rx, rz)
and each eye (yaw, pitch, roll) = radians(y, x, z).

Timing: datagrams carry no time; a recorded file is taken as one frame per line at 60 fps (the app's rate).
"""

from __future__ import annotations

import math
import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util, arkit
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "ifacialmocap-txt"
WHAT = "iFacialMocap frame text"
_ITEM = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)-(\d+(?:\.\d+)?)$")
_FIRST = re.compile(rb"^[A-Za-z][A-Za-z0-9_]*-\d+\|")
TRANSFORMS = {"head": 6, "rightEye": 3, "leftEye": 3}  # key -> values it carries


def sniff(data: bytes) -> bool:
    """A line of `name-int|` items, or one carrying `=head#`."""
    head = _util.head(data)
    first = head.split(b"\n", 1)[0]
    return bool(_FIRST.match(first)) or b"|=head#" in first


def _arkit_name(label: str) -> bool:
    """Whether an iFacialMocap weight name is one of ARKit's 52 (`_L`/`_R` spelling `Left`/`Right`)."""
    if label.endswith("_L"):
        label = label[:-2] + "Left"
    elif label.endswith("_R"):
        label = label[:-2] + "Right"
    return label in arkit.NAME_SET


def parse(data: bytes, name: str) -> WeightTrack:
    """Frames, one per non-empty line: weights /100, head and eye angles in radians; unknown items skipped."""
    lines = [(i, ln.strip()) for i, ln in enumerate(_util.text(data, name, WHAT).splitlines(), 1) if ln.strip()]
    _util.frame_count(len(lines), name)
    rows: list[dict[str, float]] = []
    poses = {key: np.zeros((len(lines), 3)) for key in TRANSFORMS}
    seen = dict.fromkeys(TRANSFORMS, False)
    for k, (i, line) in enumerate(lines):
        row: dict[str, float] = {}
        for item in line.split("|"):
            item = item.strip().lstrip("=")
            key, sep, rest = item.partition("#")
            if sep and key in TRANSFORMS:
                vals = [v.strip() for v in rest.split(",")]
                if len(vals) < TRANSFORMS[key]:
                    raise InputError(f"{name} line {i}: {key} has {len(vals)} values, expected {TRANSFORMS[key]}.")
                try:
                    poses[key][k] = [float(v) for v in vals[:3]]
                except ValueError:
                    raise InputError(f"{name} line {i}: {key} holds a value that is not a number.") from None
                seen[key] = True
                continue
            m = _ITEM.match(item)
            if m and _arkit_name(m.group(1)):
                row[m.group(1)] = float(m.group(2)) / 100.0
        if not row:
            raise InputError(f"{name} line {i} holds no blendshape weights (name-value items), so it is not an "
                             f"{WHAT} frame.")
        rows.append(row)
    names = list(dict.fromkeys(n for r in rows for n in r))
    values = np.zeros((len(rows), len(names)), np.float32)
    col = {n: j for j, n in enumerate(names)}
    for k, r in enumerate(rows):
        values[k, [col[n] for n in r]] = list(r.values())
    for key, arr in poses.items():
        _util.finite(arr, name, f"the {key} rotation")
    deg = math.pi / 180.0

    def angles(key: str, sign: float) -> np.ndarray | None:
        return (sign * poses[key][:, [1, 0, 2]] * deg).astype(np.float32) if seen[key] else None

    times = np.arange(len(rows)) / DEFAULT_FPS
    return WeightTrack(names, times, values, DEFAULT_FPS, "", angles("head", -1.0), angles("leftEye", 1.0),
                       angles("rightEye", 1.0), NAME)


LAYOUT = CaptureLayout(
    NAME, "iFacialMocap frames", (".txt",), sniff, parse,
    "iFacialMocap (iOS) UDP frames as text: name-int|... =head#rx,ry,rz,tx,ty,tz|rightEye#x,y,z|leftEye#x,y,z",
)
