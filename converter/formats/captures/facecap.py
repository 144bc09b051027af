"""Face Cap (Bannaflak, iOS) text export: a `bs` line naming the weights, then one `k` line per captured frame.

Layout (the .txt Face Cap exports beside its FBX; importers that read it, e.g. Faceit's FaceCapImporter and the
FaceCap-to-Ready-Player-Me loaders, agree on these columns):
- `bs,<name>,<name>,...`: the blendshape names in column order, ARKit's with `_L`/`_R` sides (`eyeBlink_L`).
- `k,<ms>,<head pos x,y,z>,<head rot x,y,z>,<eye L rot x,y>,<eye R rot x,y>,<one weight per bs name>`: the
  time in milliseconds since the recording started, the head's position and rotation, each eye's rotation,
  then the weights 0..1. Rotations are degrees (Faceit imports them with rotation units 'DEG').
- Other lines (`info,...` and the like) carry no animation and are skipped.

Angles: Face Cap's x, y, z are pitch, yaw, roll. Faceit brings Live Link Face angles into Face Cap's convention
as head (-pitch, -yaw, -roll) and eyes (pitch, yaw), so in the Live Link Face convention the track uses the head
is (yaw, pitch, roll) = -radians(ry, rx, rz) and each eye (yaw, pitch, 0) = radians(y, x, 0).

Timing: frames at their times as recorded; the rate is the rows' spacing snapped to a standard rate within 1%.
"""

from __future__ import annotations

import math
import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "facecap-txt"
WHAT = "Face Cap text export"
POSE_COLUMNS = 10  # after the time: head position (3), head rotation (3), left eye (2), right eye (2)
_BS = re.compile(rb"(?:^|\n)\s*bs,")
_K = re.compile(rb"(?:^|\n)\s*k,\s*[-+0-9.]")


def sniff(data: bytes) -> bool:
    """Text with a `bs,` names line and `k,<ms>` frame lines."""
    head = _util.head(data)
    return bool(_BS.search(head)) and bool(_K.search(head))


def parse(data: bytes, name: str) -> WeightTrack:
    """Face Cap's `bs` names and `k` frames: weights, head and eye angles (degrees in the file, radians here)."""
    lines = [ln.strip() for ln in _util.text(data, name, WHAT).splitlines()]
    names: list[str] | None = None
    frames: list[list[str]] = []
    numbers: list[int] = []  # 1-based line numbers of the frames, for messages
    for i, line in enumerate(lines, 1):
        cells = [c.strip() for c in line.split(",")]
        if cells[0] == "bs":
            if names is not None:
                raise InputError(f"{name} line {i}: a second bs line; the export holds one list of names.")
            names = [c for c in cells[1:] if c]
        elif cells[0] == "k":
            frames.append(cells[1:])
            numbers.append(i)
    if names is None or not names:
        raise InputError(f"{name} has no bs line naming the blendshapes, so it is not a complete {WHAT}.")
    if not frames:
        raise InputError(f"{name} names its blendshapes but has no k frame lines.")
    _util.frame_count(len(frames), name)
    width = 1 + POSE_COLUMNS + len(names)
    for cells, i in zip(frames, numbers):
        if len(cells) != width:
            raise InputError(f"{name} line {i} has {len(cells)} values after k but {width} are expected (time, 10 "
                             f"pose values, {len(names)} weights); the file is truncated or edited.")
    try:
        table = np.array(frames, np.float64)
    except ValueError:
        k = next(k for k, cells in enumerate(frames) if not all(_util.is_float(c) for c in cells))
        raise InputError(f"{name} line {numbers[k]} holds a value that is not a number.") from None
    bad = ~np.isfinite(table)
    if bad.any():
        k = int(np.argwhere(bad)[0][0])
        raise InputError(f"{name} line {numbers[k]} holds NaN or infinite values; re-export the take.")
    ms = table[:, 0]
    if len(ms) > 1 and np.any(np.diff(ms) <= 0):
        k = int(np.argmax(np.diff(ms) <= 0)) + 1
        raise InputError(f"{name} line {numbers[k]}: the time {ms[k]:g} ms is not after the one before.")
    times = (ms - ms[0]) / 1000.0
    fps = _util.spacing_rate(times) or DEFAULT_FPS
    deg = math.pi / 180.0
    rot = table[:, 4:7]
    head = (-rot[:, [1, 0, 2]] * deg).astype(np.float32)

    def eye(x: int) -> np.ndarray:
        e = np.zeros((len(table), 3))
        e[:, 0], e[:, 1] = table[:, x + 1] * deg, table[:, x] * deg
        return e.astype(np.float32)

    return WeightTrack(names, times, table[:, 1 + POSE_COLUMNS:].astype(np.float32), float(fps), "", head,
                       eye(7), eye(9), NAME)


LAYOUT = CaptureLayout(
    NAME, "Face Cap TXT", (".txt",), sniff, parse,
    "Face Cap (Bannaflak, iOS) text export: bs,<names> then k,<ms>,<head pos>,<head rot>,<eyes>,<weights>",
)
