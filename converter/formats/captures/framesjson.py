"""Per-frame weight JSON: a list of frames, each with a time and its named weights, or an object keyed by time.

Layouts read (what ARKit recorders dump from ARFaceAnchor.blendShapes, {BlendShapeLocation.rawValue: NSNumber},
e.g. "eyeBlink_L" or "eyeBlinkLeft"):
- `[{"time" | "timestamp" | "t" | "timeStamp": t, "blendshapes" | "blendShapes" | "weights" | "blendshape":
  {name: w} or [{"name" | "categoryName" | "blendShapeLocation": n, "score" | "value" | "weight": w}]}, ...]`,
  optionally wrapped as `{"fps" | "frameRate": r, "frames" | "blendshapes" | "blendShapes" | "data": [...]}`.
  `time` is seconds; `timestamp` is milliseconds when its steps exceed a second's worth (Date.now() and
  performance.now() recorders), else seconds.
- A time-keyed object `{"<seconds>": {name: w, ...}, ...}` (BlendShapesRecorder-style dumps).

Timing: frames at their times as written; the rate is the stated one, else the rows' spacing (snapped to a
standard rate within 1%); frames without times are one per frame at the stated rate or 60 fps.
"""

from __future__ import annotations

import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "frames-json"
WHAT = "weight JSON"
TIME_KEYS = ("time", "timestamp", "t", "timeStamp")
SHAPE_KEYS = ("blendshapes", "blendShapes", "weights", "blendshape")
WRAP_KEYS = ("frames", "blendshapes", "blendShapes", "data")
_KEYS = re.compile(rb'"(blendshapes|blendShapes|weights|blendshape|frames|time|timestamp|timeStamp)"\s*:')
_TIME_KEYED = re.compile(rb'^\{\s*"[-+]?\d+(\.\d*)?([eE][-+]?\d+)?"\s*:\s*\{')


def sniff(data: bytes) -> bool:
    """JSON naming a frame list's keys (time, blendshapes, weights, frames), or an object keyed by seconds."""
    head = _util.head(data)
    return head[:1] in (b"[", b"{") and (bool(_KEYS.search(head)) or bool(_TIME_KEYED.match(head)))


def parse(data: bytes, name: str) -> WeightTrack:
    """A per-frame weight JSON in one of the layouts the module docstring lists."""
    doc = _util.json_doc(data, name, WHAT)
    fps = None
    frames = doc
    if isinstance(doc, dict):
        for key in WRAP_KEYS:
            if isinstance(doc.get(key), list):
                frames = doc[key]
                fps = doc.get("fps", doc.get("frameRate"))
                break
        else:
            keyed = _time_keyed(doc)
            if keyed is not None:
                frames = keyed
    if isinstance(frames, list) and frames and all(isinstance(f, dict) for f in frames):
        return frame_list(frames, fps, name)
    raise InputError(f"{name} is JSON but not a weight layout facesvg knows (a list of frames with a time and "
                     "blendshapes, or an object keyed by seconds); convert it to one of those.")


def _time_keyed(doc: dict) -> list[dict] | None:
    """{"0.016": {name: w}, ...} as a frame list, or None when the keys are not all numbers."""
    if not doc or not all(_util.is_float(k) and isinstance(v, dict) for k, v in doc.items()):
        return None
    return [{"time": float(k), "blendshapes": v} for k, v in sorted(doc.items(), key=lambda kv: float(kv[0]))]


def frame_list(frames: list[dict], fps, name: str) -> WeightTrack:
    """A track from frames of {time key: t, shape key: {name: w} or [{name, score}]} (keys as frame 0 spells them)."""
    _util.frame_count(len(frames), name)
    time_key = next((k for k in TIME_KEYS if k in frames[0]), None)
    shape_key = next((k for k in SHAPE_KEYS if k in frames[0]), None)
    if shape_key is None:
        raise InputError(f"{name}: frame 0 has no blendshapes/weights entry; each frame needs "
                         "{\"time\": seconds, \"blendshapes\": {name: weight}}.")
    rows: list[dict] = []
    for k, f in enumerate(frames):
        entry = f.get(shape_key)
        if isinstance(entry, dict):
            row = entry
        elif isinstance(entry, list) and all(isinstance(e, dict) for e in entry):
            row = {}
            for e in entry:
                label = e.get("name", e.get("categoryName", e.get("blendShapeLocation")))
                if not isinstance(label, str):
                    raise InputError(f"{name}: frame {k} has a blendshape entry without a name.")
                row[label] = e.get("score", e.get("value", e.get("weight")))
        else:
            raise InputError(f"{name}: frame {k} has no {shape_key} object; every frame needs one.")
        rows.append(row)
    names = list(dict.fromkeys(n for r in rows for n in r))
    if not names:
        raise InputError(f"{name}: the frames hold no blendshape weights.")
    values = np.zeros((len(rows), len(names)), np.float64)
    col = {n: j for j, n in enumerate(names)}
    for k, r in enumerate(rows):
        for n, v in r.items():
            if not _util.is_number(v):
                raise InputError(f"{name}: frame {k}, weight {n!r} is {v!r}, not a finite number.")
            values[k, col[n]] = v
    stated = _util.fps_value(fps, name) if fps is not None else None
    if time_key is not None:
        try:
            t = np.array([float(f[time_key]) for f in frames], np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{name}: every frame needs a numeric {time_key!r}.") from None
        if not np.isfinite(t).all() or (len(t) > 1 and np.any(np.diff(t) <= 0)):
            raise InputError(f"{name}: frame times are not increasing finite numbers.")
        t = t - t[0]
        if time_key == "timestamp" and len(t) > 1 and np.median(np.diff(t)) > 1.0:
            t = t / 1000.0  # milliseconds
        rate = stated or _util.spacing_rate(t) or DEFAULT_FPS
    else:
        rate = stated or DEFAULT_FPS
        t = np.arange(len(rows)) / rate
    return WeightTrack(names, t, values.astype(np.float32), float(rate), source=NAME)



LAYOUT = CaptureLayout(
    NAME, "Per-frame weight JSON", (".json",), sniff, parse,
    "ARKit recorders' frame lists ([{time, blendshapes: {name: weight}}]) and time-keyed objects",
)
