"""Blendshape weight captures (ARKit-style named weights over time): Live Link Face CSV and weight JSON layouts.

Pure parsing: a file becomes a WeightTrack (names, times, values, optional head/eye angles); nothing 3D here.

Layouts read, each as the tool that writes it documents or emits it:
- Live Link Face CSV (Epic's iOS app): `Timecode` HH:MM:SS:FF.mmm (frame FF, .mmm the sub-frame fraction),
  `BlendShapeCount`, the 52 ARKit weights with capitalised names (`EyeBlinkLeft` ... `TongueOut`), then
  `HeadYaw, HeadPitch, HeadRoll, LeftEyeYaw, LeftEyePitch, LeftEyeRoll, RightEyeYaw, ...`. The angles are
  normalised: -1..1 stands for -90..90 degrees (drivers of the app's stream scale them by pi/2, e.g.
  polyvox_filament's Live Link Face bone drivers; MediaPipe4U documents the same curves as -1..1).
- NVIDIA Audio2Face blendshape export: `{"exportFps", "trackPath", "numPoses", "numFrames", "facsNames": [K],
  "weightMat": [numFrames][numPoses]}` (the layout A2F's "Export blendshapes" JSON writes; see e.g. the
  Audio2FaceExportData interface of Babylon.js integrations).
- Per-frame lists: `[{"time" | "timestamp": t, "blendshapes" | "blendShapes" | "weights": {name: w} or
  [{"name" | "categoryName": n, "score" | "value" | "weight": w}]}]`, optionally wrapped as
  `{"fps": .., "frames": [...]}`. This is what ARFaceAnchor.blendShapes dumps ({BlendShapeLocation.rawValue:
  NSNumber}, e.g. "eyeBlink_L") and MediaPipe FaceLandmarker recorders (categoryName/score, timestamp in ms)
  write.
- A time-keyed object `{"<seconds>": {name: w, ...}, ...}` (ARKit BlendShapesRecorder-style dumps).
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from converter.errors import InputError
from converter.userfiles import read_bytes

DEFAULT_FPS = 60.0  # ARKit face tracking runs at 60 Hz; used when a capture gives no rate
MAX_FRAMES = 1_000_000
LLF_ANGLE_UNIT = math.pi / 2  # radians per Live Link Face angle unit (normalised -1..1 = -90..90 degrees)
LLF_HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")
LLF_EYES = {side: tuple(f"{side}Eye{a}" for a in ("Yaw", "Pitch", "Roll")) for side in ("Left", "Right")}
TIMECODE = re.compile(r"^\s*(\d+):(\d+):(\d+)[:;.](\d+)(?:\.(\d+))?\s*$")


@dataclass(frozen=True, eq=False)
class WeightTrack:
    """Named blendshape weights over time, with optional head and eye rotations (yaw, pitch, roll) in radians."""

    names: list[str]
    times: np.ndarray  # float64 (T,) seconds from the first frame
    values: np.ndarray  # float32 (T, K)
    fps: float
    start_timecode: str = ""  # the first frame's timecode as written, or ""
    head: np.ndarray | None = None  # float32 (T, 3) yaw, pitch, roll in radians
    eye_left: np.ndarray | None = None  # float32 (T, 3) yaw, pitch, roll in radians
    eye_right: np.ndarray | None = None
    source: str = ""  # which layout the file had: livelinkface-csv, audio2face-json, frames-json, ...

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.values.shape[0])

    def sampled(self, fps: float) -> WeightTrack:
        """The track resampled (linear) onto a regular grid k / fps covering its time span."""
        span = float(self.times[-1] - self.times[0]) if self.n_frames > 1 else 0.0
        n = int(math.floor(span * fps + 1e-6)) + 1
        t = self.times[0] + np.arange(n) / fps

        def interp(a: np.ndarray | None) -> np.ndarray | None:
            if a is None:
                return None
            if self.n_frames == 1:
                return np.repeat(a[:1], n, axis=0)
            cols = [np.interp(t, self.times, a[:, j]) for j in range(a.shape[1])]
            return np.stack(cols, axis=1).astype(np.float32)

        return WeightTrack(self.names, t - t[0], interp(self.values), float(fps), self.start_timecode,
                           interp(self.head), interp(self.eye_left), interp(self.eye_right), self.source)


def read_weights(path: str | Path) -> WeightTrack:
    """Read a weight capture file (Live Link Face CSV or an ARKit weight JSON) into a WeightTrack."""
    path = Path(path)
    data = read_bytes(path, "weights file")
    return parse_weights(data, path.name)


def parse_weights(data: bytes, name: str = "weights") -> WeightTrack:
    """A WeightTrack from the bytes of a capture; the layout is recognised by content."""
    text = _text(data, name)
    head = text.lstrip()[:1]
    if head in ("{", "["):
        return parse_weight_json(text, name)
    return parse_livelinkface_csv(text, name)


def is_capture(data: bytes) -> str | None:
    """A short description when the bytes look like a weight capture (so a mesh loader can say so), else None."""
    head = data[:65536].removeprefix(b"\xef\xbb\xbf").lstrip()
    first = head.split(b"\n", 1)[0]
    if first.startswith(b"Timecode,") and b"BlendShapeCount" in first:
        return "a Live Link Face capture CSV"
    if head[:1] in (b"{", b"["):
        if b'"facsNames"' in head and b'"weightMat"' in head:
            return "an Audio2Face blendshape weight export"
        if re.search(rb'"(blendshapes|blendShapes|categoryName)"', head):
            return "an ARKit blendshape weight capture"
    return None


# -- Live Link Face CSV -------------------------------------------------------------------------------------
def parse_livelinkface_csv(text: str, name: str = "capture.csv") -> WeightTrack:
    """Live Link Face's CSV: timecode -> times, fps and start; 52 weights; head and eye angles in radians."""
    rows = list(csv.reader(io.StringIO(text)))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError(f"{name} is empty; give a Live Link Face CSV or an ARKit weight JSON.")
    header = [c.strip() for c in rows[0]]
    if "Timecode" not in header or "BlendShapeCount" not in header:
        missing = " and ".join(c for c in ("Timecode", "BlendShapeCount") if c not in header)
        raise InputError(f"{name} is not a Live Link Face CSV (no {missing} column); give the CSV the app "
                         "exports or an ARKit weight JSON.")
    body = rows[1:]
    if not body:
        raise InputError(f"{name} has a header but no frames.")
    if len(body) > MAX_FRAMES:
        raise InputError(f"{name} has {len(body)} frames, more than {MAX_FRAMES}; trim the capture.")
    for k, r in enumerate(body):
        if len(r) != len(header):
            raise InputError(f"{name} row {k + 2} has {len(r)} cells but the header has {len(header)}; "
                             "the file is truncated or edited.")
    tc_col = header.index("Timecode")
    angle_cols = set(LLF_HEAD) | set(LLF_EYES["Left"]) | set(LLF_EYES["Right"])
    weight_cols = [i for i, c in enumerate(header) if c not in ("Timecode", "BlendShapeCount") and c not in angle_cols]
    if not weight_cols:
        raise InputError(f"{name} has no blendshape weight columns.")
    numeric = [i for i in range(len(header)) if i != tc_col]
    table = np.empty((len(body), len(header)), np.float64)
    for i in numeric:
        try:
            table[:, i] = [float(r[i]) for r in body]
        except ValueError:
            bad = next(k for k, r in enumerate(body) if not _is_float(r[i]))
            raise InputError(
                f"{name} row {bad + 2}, column {header[i]}: {body[bad][i][:30]!r} is not a number."
            ) from None
    if not np.isfinite(table[:, numeric]).all():
        k, j = np.argwhere(~np.isfinite(table[:, numeric]))[0]
        raise InputError(f"{name} row {k + 2}, column {header[numeric[j]]} is NaN or infinite; re-export the take.")
    times, fps, start = _timecodes([r[tc_col] for r in body], name)

    def angles(cols: tuple[str, ...]) -> np.ndarray | None:
        if not all(c in header for c in cols):
            return None
        return (table[:, [header.index(c) for c in cols]] * LLF_ANGLE_UNIT).astype(np.float32)

    return WeightTrack([header[i] for i in weight_cols], times, table[:, weight_cols].astype(np.float32), fps,
                       start, angles(LLF_HEAD), angles(LLF_EYES["Left"]), angles(LLF_EYES["Right"]),
                       "livelinkface-csv")


def _timecodes(cells: list[str], name: str) -> tuple[np.ndarray, float, str]:
    """Seconds from the first frame, the frame rate and the start timecode of HH:MM:SS:FF[.fff] cells.

    The rate is the smallest standard rate above every FF; times are whole seconds plus (FF + fraction) / rate.
    """
    parsed = []
    for k, c in enumerate(cells):
        m = TIMECODE.match(c)
        if not m:
            raise InputError(f"{name} row {k + 2}: timecode {c[:30]!r} is not HH:MM:SS:FF.mmm.")
        h, mi, s, f = (int(m.group(i)) for i in range(1, 5))
        frac = float("0." + m.group(5)) if m.group(5) else 0.0
        parsed.append((h * 3600 + mi * 60 + s, f + frac))
    arr = np.array(parsed, np.float64)
    max_ff = int(arr[:, 1].max())
    # FF counts 0..rate-1: a take that crosses a second shows the rate; a shorter one is taken at the app's 60.
    floor = max_ff + 1 if np.ptp(arr[:, 0]) > 0 else max(max_ff + 1, int(DEFAULT_FPS))
    rate = next((r for r in (24, 25, 30, 48, 50, 60, 120, 240) if r >= floor), floor)
    t = arr[:, 0] + arr[:, 1] / rate
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise InputError(f"{name} row {k + 3}: the timecode does not increase ({cells[k + 1].strip()} after "
                         f"{cells[k].strip()}); the take is edited or spans midnight.")
    fps = float(rate)
    return t - t[0], fps, cells[0].strip()


# -- JSON -------------------------------------------------------------------------------------------------
def parse_weight_json(text: str, name: str = "capture.json") -> WeightTrack:
    """An ARKit weight JSON in one of the layouts the module docstring lists."""
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"{name} is not valid JSON ({str(exc)[:60]}).") from None
    if isinstance(doc, dict) and "facsNames" in doc and "weightMat" in doc:
        return _audio2face(doc, name)
    fps = None
    frames = doc
    if isinstance(doc, dict):
        for key in ("frames", "blendshapes", "blendShapes", "data"):
            if isinstance(doc.get(key), list):
                frames = doc[key]
                fps = doc.get("fps", doc.get("frameRate"))
                break
        else:
            keyed = _time_keyed(doc)
            if keyed is not None:
                frames = keyed
    if isinstance(frames, list) and frames and all(isinstance(f, dict) for f in frames):
        return _frame_list(frames, fps, name)
    raise InputError(f"{name} is JSON but not a weight layout facesvg knows (Audio2Face facsNames/weightMat, or a "
                     "list of frames with time and blendshapes); convert it to one of those.")


def _audio2face(doc: dict, name: str) -> WeightTrack:
    names = doc["facsNames"]
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or not names:
        raise InputError(f"{name}: facsNames must be a list of blendshape names.")
    mat = _matrix(doc["weightMat"], len(names), name, "weightMat")
    fps = _fps(doc.get("exportFps"), name)
    n = doc.get("numFrames")
    if n is not None and n != len(mat):
        raise InputError(f"{name}: numFrames is {n} but weightMat has {len(mat)} rows; the export is truncated.")
    times = np.arange(len(mat)) / fps
    return WeightTrack(list(names), times, mat, fps, source="audio2face-json")


def _time_keyed(doc: dict) -> list[dict] | None:
    """{"0.016": {name: w}, ...} as a frame list, or None when the keys are not all numbers."""
    if not doc or not all(_is_float(k) and isinstance(v, dict) for k, v in doc.items()):
        return None
    return [{"time": float(k), "blendshapes": v} for k, v in sorted(doc.items(), key=lambda kv: float(kv[0]))]


def _frame_list(frames: list[dict], fps, name: str) -> WeightTrack:
    if len(frames) > MAX_FRAMES:
        raise InputError(f"{name} has {len(frames)} frames, more than {MAX_FRAMES}; trim the capture.")
    time_key = next((k for k in ("time", "timestamp", "t", "timeStamp") if k in frames[0]), None)
    shape_key = next((k for k in ("blendshapes", "blendShapes", "weights", "blendshape") if k in frames[0]), None)
    if shape_key is None:
        raise InputError(f"{name}: frame 0 has no blendshapes/weights entry; each frame needs "
                         "{\"time\": seconds, \"blendshapes\": {name: weight}}.")
    rows: list[dict[str, float]] = []
    for k, f in enumerate(frames):
        entry = f.get(shape_key)
        if isinstance(entry, dict):
            row = entry
        elif isinstance(entry, list) and all(isinstance(e, dict) for e in entry):
            row = {}
            for e in entry:
                label = e.get("name", e.get("categoryName", e.get("blendShapeLocation")))
                value = e.get("score", e.get("value", e.get("weight")))
                if not isinstance(label, str):
                    raise InputError(f"{name}: frame {k} has a blendshape entry without a name.")
                row[label] = value
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
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"{name}: frame {k}, weight {n!r} is {v!r}, not a finite number.")
            values[k, col[n]] = v
    if time_key is not None:
        try:
            t = np.array([float(f[time_key]) for f in frames], np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{name}: every frame needs a numeric {time_key!r}.") from None
        if not np.isfinite(t).all() or (len(t) > 1 and np.any(np.diff(t) <= 0)):
            raise InputError(f"{name}: frame times are not increasing finite numbers.")
        t = t - t[0]
        if time_key == "timestamp" and len(t) > 1 and np.median(np.diff(t)) > 1.0:
            t = t / 1000.0  # milliseconds (Date.now()/performance.now() recorders)
        measured = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else DEFAULT_FPS
        rate = _fps(fps, name) if fps is not None else measured
    else:
        rate = _fps(fps, name) if fps is not None else DEFAULT_FPS
        t = np.arange(len(rows)) / rate
    return WeightTrack(names, t, values.astype(np.float32), float(rate), source="frames-json")


def _matrix(rows, k: int, name: str, what: str) -> np.ndarray:
    if not isinstance(rows, list) or not rows:
        raise InputError(f"{name}: {what} must be a non-empty list of frames.")
    if len(rows) > MAX_FRAMES:
        raise InputError(f"{name} has {len(rows)} frames, more than {MAX_FRAMES}; trim the capture.")
    try:
        mat = np.array(rows, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: {what} holds values that are not numbers, or rows of different lengths.") from None
    if mat.ndim != 2 or mat.shape[1] != k:
        raise InputError(f"{name}: {what} rows must have one weight per name ({k}), got shape {mat.shape}.")
    if not np.isfinite(mat).all():
        r, c = np.argwhere(~np.isfinite(mat))[0]
        raise InputError(f"{name}: {what} frame {r}, weight {c} is NaN or infinite.")
    return mat.astype(np.float32)


def _fps(value, name: str) -> float:
    if value is None:
        return DEFAULT_FPS
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value <= 1000):
        raise InputError(f"{name}: the frame rate {value!r} is not a positive number.")
    return float(value)


def _text(data: bytes, name: str) -> str:
    if not data.strip():
        raise InputError(f"{name} is empty; give a Live Link Face CSV or an ARKit weight JSON.")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{name} is not UTF-8 text; give a Live Link Face CSV or an ARKit weight JSON.") from None


def _is_float(s) -> bool:
    try:
        float(s)
        return True
    except (TypeError, ValueError):
        return False
