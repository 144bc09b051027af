"""Azure Speech viseme blend shapes: the `Animation` JSON of the SDK's VisemeReceived events (FacialExpression).

Layout (Microsoft Learn, "Get facial position with viseme", 3D blend shapes): each event's Animation is
`{"FrameIndex": n, "BlendShapes": [[55 numbers] per frame]}` at 60 frames a second, FrameIndex counting the frames
before the chunk. A saved take is those chunks one after another: a JSON list of them, or one object per line
(or simply concatenated). Chunks are put in FrameIndex order; a gap or overlap between them is an error (an event
was lost or saved twice).

The 55 columns are, in the documented order, ARKit's 52 weights (eyeBlinkLeft ... tongueOut, the order
`arkit.NAMES` lists) then headRoll, leftEyeRoll, rightEyeRoll. The page gives every column as "decimal values
between 0 to 1" and no angle unit for the three rolls. They carry the names of the roll members of ARKit's face
curve set that Unreal's Live Link Face uses (HeadRoll, LeftEyeRoll, RightEyeRoll), whose unit is the normalised
-1..1 = -90..90 degrees; so they are read in that unit (radians = value x pi / 2, ROLL_UNIT), as roll (about the
forward axis) of the head and of each eye, with yaw and pitch 0. (TalkingHead's Azure example feeds headRoll to a
bone in radians unscaled; its magnitudes are small either way.)
"""

from __future__ import annotations

import math

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util, reading
from converter.formats.captures.arkit import NAMES as ARKIT_NAMES
from converter.formats.captures.base import CaptureLayout, WeightTrack

WHAT = "Azure viseme blend shape animation"
FPS = 60.0  # "Each frame (in 60 FPS) contains an array of 55 facial positions"
ROLLS = ("headRoll", "leftEyeRoll", "rightEyeRoll")
COLUMNS = (*ARKIT_NAMES, *ROLLS)  # 55
ROLL_UNIT = math.pi / 2  # radians per roll unit (ARKit face-curve normalisation, -1..1 = -90..90 degrees)


def sniff(data: bytes) -> bool:
    """True for JSON with Azure's FrameIndex and BlendShapes keys."""
    head = _util.head(data)
    return head[:1] in (b"{", b"[") and b'"FrameIndex"' in head and b'"BlendShapes"' in head


def parse(data: bytes, name: str = "visemes.json") -> WeightTrack:
    """Azure viseme Animation chunks as a WeightTrack: 52 ARKit weights, head and eye roll in radians, 60 fps."""
    docs = reading.json_docs(data, name, WHAT)
    chunks = [c for d in docs for c in (d if isinstance(d, list) else [d])]
    if not chunks:
        raise InputError(f"{name} holds no viseme animation chunks.")
    parts: list[tuple[int, np.ndarray]] = []
    for k, chunk in enumerate(chunks):
        if not isinstance(chunk, dict) or "BlendShapes" not in chunk:
            raise InputError(f"{name}: chunk {k} is not an Azure viseme Animation object "
                             "({\"FrameIndex\": n, \"BlendShapes\": [[55 numbers], ...]}).")
        index = chunk.get("FrameIndex", 0)
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise InputError(f"{name}: chunk {k} has FrameIndex {index!r:.30}, not a frame count.")
        rows = chunk["BlendShapes"]
        if rows == []:
            continue
        parts.append((index, reading.matrix(rows, len(COLUMNS), name, f"chunk {k} (FrameIndex {index}) BlendShapes")))
    if not parts:
        raise InputError(f"{name}: every chunk's BlendShapes is empty; the take has no frames.")
    parts.sort(key=lambda p: p[0])
    expected = parts[0][0]
    for index, mat in parts:
        if index != expected:
            what = "missing" if index > expected else "repeated"
            raise InputError(f"{name}: a chunk starts at frame {index} but the chunks before end at frame {expected}; "
                             f"frames are {what} (a viseme event was lost or saved twice).")
        expected = index + len(mat)
    table = np.concatenate([m for _, m in parts])
    _util.frame_count(len(table), name)
    weights = table[:, : len(ARKIT_NAMES)].astype(np.float32)
    rolls = (table[:, len(ARKIT_NAMES):] * ROLL_UNIT).astype(np.float32)
    zeros = np.zeros((len(table), 2), np.float32)

    def roll_only(col: int) -> np.ndarray:
        return np.column_stack([zeros, rolls[:, col]])

    return WeightTrack(list(ARKIT_NAMES), np.arange(len(table)) / FPS, weights, FPS, head=roll_only(0),
                       eye_left=roll_only(1), eye_right=roll_only(2), source=LAYOUT.name)


LAYOUT = CaptureLayout(
    name="azure-viseme-json",
    label="Azure viseme blend shapes",
    extensions=(".json", ".jsonl"),
    sniff=sniff,
    parse=parse,
    doc="Microsoft Learn, Speech service: Get facial position with viseme (3D blend shapes, 55 facial positions)",
)
