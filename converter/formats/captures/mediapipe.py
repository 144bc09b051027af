"""MediaPipe FaceLandmarker blendshapes: categories of (name, score), one frame or a timed list of frames.

FaceLandmarker (output_face_blendshapes) gives, per detected face, 52 categories: `_neutral` first, then the
ARKit names in alphabetical order (browDownLeft ... noseSneerRight), no tongueOut; each has `index`, `score`
(0..1), `categoryName` (JS/JSON; `category_name` in Python) and `displayName`. Layouts read:
- one frame: a list of categories; `{"categories": [...]}`; `{"faceBlendshapes" | "face_blendshapes":
  [face, ...]}` (a face is a list of categories or `{"categories": [...]}`); `{"people": [[category, ...],
  ...]}` (an app's dump: one list per face, categories as `{name, score}`). The first face is read.
- a recording: a list of frames (or `{"fps": r, "frames": [...]}`), each `{time key: t, shapes key: one frame
  as above}`, time keys `timestampMs` / `timestamp_ms` (milliseconds, MediaPipe's video timestamps),
  `timestamp` (milliseconds when its steps exceed a second's worth, else seconds) or `time` (seconds), shapes
  keys `blendshapes`, `blendShapes`, `faceBlendshapes`, `face_blendshapes` or `categories`.
- scores may be numbers or numeric strings (one app writes `"score": "0.838"`).
`_neutral` is dropped (it is no shape). The real files this was checked on: mediapipe_blendshapes_people.json
and mediapipe_blendshapes_flat.json (V-Sekai mediapipe-labeler).

Timing: a single frame is one frame at 60 fps; a recording's frames sit at their timestamps, at the stated
rate or the timestamps' spacing snapped to a standard rate within 1%.
"""

from __future__ import annotations

import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "mediapipe-json"
WHAT = "MediaPipe blendshape JSON"
NEUTRAL = "_neutral"
NAME_KEYS = ("categoryName", "category_name", "name", "displayName", "display_name")
FACE_KEYS = ("faceBlendshapes", "face_blendshapes", "people")
SHAPE_KEYS = ("blendshapes", "blendShapes", "faceBlendshapes", "face_blendshapes", "categories")
TIME_KEYS = {"timestampMs": 1e-3, "timestamp_ms": 1e-3, "timestamp": None, "time": 1.0}
_SIGNS = re.compile(rb'"(categoryName|category_name|faceBlendshapes|face_blendshapes|_neutral)"')


def sniff(data: bytes) -> bool:
    """JSON naming MediaPipe's category fields (categoryName / category_name), its result keys or `_neutral`."""
    head = _util.head(data)
    return head[:1] in (b"[", b"{") and bool(_SIGNS.search(head))


def parse(data: bytes, name: str) -> WeightTrack:
    """One FaceLandmarker result or a timed list of them, `_neutral` dropped."""
    doc = _util.json_doc(data, name, WHAT)
    fps = None
    if isinstance(doc, dict) and isinstance(doc.get("frames"), list):
        fps, doc = doc.get("fps", doc.get("frameRate")), doc["frames"]
    if isinstance(doc, list) and doc and all(isinstance(f, dict) for f in doc) and not _is_category(doc[0]):
        return _recording(doc, fps, name)
    row = _frame(doc, name, "the file")
    return _track([row], np.zeros(1), DEFAULT_FPS, name)


def _is_category(entry: dict) -> bool:
    return "score" in entry and any(k in entry for k in NAME_KEYS)


def _frame(value, name: str, where: str) -> dict[str, float]:
    """{name: score} of one result: a category list, {"categories"}, or a face list under a result key."""
    if isinstance(value, dict):
        if isinstance(value.get("categories"), list):
            return _frame(value["categories"], name, where)
        key = next((k for k in FACE_KEYS if k in value), None)
        if key is None:
            raise InputError(f"{name}: {where} has no categories, faceBlendshapes or people list of blendshapes.")
        faces = value[key]
        if not isinstance(faces, list):
            raise InputError(f"{name}: {where}'s {key} is not a list of faces.")
        if not faces:
            raise InputError(f"{name}: {where} found no face ({key} is empty).")
        return _frame(faces[0], name, where)
    if isinstance(value, list) and value and (isinstance(value[0], list) or
                                              (isinstance(value[0], dict) and "categories" in value[0])):
        return _frame(value[0], name, where)  # a list of faces: the first one
    if not isinstance(value, list) or not value or not all(isinstance(c, dict) for c in value):
        raise InputError(f"{name}: {where} is not a list of blendshape categories ({{categoryName, score}}).")
    row: dict[str, float] = {}
    for c in value:
        label = next((c[k] for k in NAME_KEYS if isinstance(c.get(k), str)), None)
        if label is None:
            raise InputError(f"{name}: {where} has a category without a name.")
        row[label] = _util.number(c.get("score"), name, f"the score of {label!r} in {where}", strings=True)
    row.pop(NEUTRAL, None)
    if not row:
        raise InputError(f"{name}: {where} holds only {NEUTRAL}, no blendshape.")
    return row


def _recording(frames: list[dict], fps, name: str) -> WeightTrack:
    """Frames of {timestamp: t, blendshapes: result}: times in seconds, the rate stated or measured."""
    _util.frame_count(len(frames), name)
    first = frames[0]
    shape_key = next((k for k in SHAPE_KEYS if k in first), None)
    if shape_key is None:
        raise InputError(f"{name}: frame 0 has no blendshapes entry ({', '.join(SHAPE_KEYS)}).")
    rows = []
    for k, f in enumerate(frames):
        value = f.get(shape_key)
        rows.append(_frame({"categories": value} if shape_key == "categories" else value, name, f"frame {k}"))
    stated = _util.fps_value(fps, name) if fps is not None else None
    time_key = next((k for k in TIME_KEYS if k in first), None)
    if time_key is None:
        rate = stated or DEFAULT_FPS
        return _track(rows, np.arange(len(rows)) / rate, rate, name)
    t = _util.increasing(np.array([_util.number(f.get(time_key), name, f"frame {k}'s {time_key}")
                                   for k, f in enumerate(frames)]), name, f"{time_key} values")
    scale = TIME_KEYS[time_key]
    if scale is None:  # "timestamp": milliseconds unless its steps are already fractions of a second
        scale = 1e-3 if len(t) > 1 and np.median(np.diff(t)) > 1.0 else 1.0
    t = t * scale
    return _track(rows, t, stated or _util.spacing_rate(t) or DEFAULT_FPS, name)


def _track(rows: list[dict[str, float]], times: np.ndarray, fps: float, name: str) -> WeightTrack:
    names = list(dict.fromkeys(n for r in rows for n in r))
    values = np.zeros((len(rows), len(names)), np.float32)
    col = {n: j for j, n in enumerate(names)}
    for k, r in enumerate(rows):
        values[k, [col[n] for n in r]] = list(r.values())
    return WeightTrack(names, np.asarray(times, np.float64), values, float(fps), source=NAME)


LAYOUT = CaptureLayout(
    NAME, "MediaPipe blendshapes JSON", (".json",), sniff, parse,
    "MediaPipe FaceLandmarker face blendshapes (categoryName/score, _neutral first), one result or timed frames",
)
