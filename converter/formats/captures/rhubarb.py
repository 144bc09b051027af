"""Rhubarb Lip Sync output (JSON or TSV mouth cues) as ARKit weights, through a mouth-shape table.

Layouts (Rhubarb's README, "Output formats"):
- JSON: `{"metadata": {"soundFile", "duration"}, "mouthCues": [{"start": s, "end": s, "value": "A".."H" | "X"}]}`;
  each cue ends where the next starts.
- TSV (the default export): `start<TAB>shape` lines from 0.00; the last line is the end of the recording (its
  shape is always the closed X or A).

Each shape is a set of ARKit weights (SHAPES, below); the cues are a step function of those weights, sampled at
60 fps (or at `metadata.fps` / `metadata.frameRate` when the file gives a rate) with short linear cross-fades:
the steps are averaged over a CROSSFADE-wide window around each frame time, which is exactly a linear ramp of
that width centred on every cue change (and a blend of the neighbours for a cue shorter than it). Frame k is at
k / fps for k < duration x fps, so the frames cover the recording; a gap between JSON cues holds the rest shape X.
"""

from __future__ import annotations

import math
import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.arkit import NAMES as ARKIT_NAMES
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

WHAT = "Rhubarb Lip Sync file"
CROSSFADE = 0.04  # seconds each change of mouth shape ramps over (Rhubarb's shortest cues are a few 0.01 s)
TSV_LINE = re.compile(r"^\s*(\S+)\s+(\S+)\s*$")
_TSV_SNIFF = re.compile(rb"^\d+(?:\.\d+)?\t[A-HX]\r?$")


def _pair(base: str, w: float) -> dict[str, float]:
    return {f"{base}Left": w, f"{base}Right": w}


# Rhubarb's nine mouth shapes (README "Mouth shapes"; the Preston Blair names its --datUsePrestonBlair writes in
# brackets) as ARKit weights 0..1. The jaw carries the opening; the lips are drawn by the ARKit lip shapes.
SHAPES: dict[str, dict[str, float]] = {
    # A [MBP]: closed mouth for P, B, M with slight pressure between the lips: lips pressed, a little rolled in.
    "A": {**_pair("mouthPress", 0.5), "mouthRollLower": 0.15, "mouthRollUpper": 0.1},
    # B [etc]: slightly open mouth, clenched teeth (K, S, T; also the EE of "bee"): jaw almost shut, lips parted
    # from the teeth and spread wide.
    "B": {"jawOpen": 0.08, **_pair("mouthUpperUp", 0.35), **_pair("mouthLowerDown", 0.35),
          **_pair("mouthStretch", 0.3), **_pair("mouthSmile", 0.15)},
    # C [E]: open mouth (EH in "men", AE in "bat"); the in-between from A or B to D.
    "C": {"jawOpen": 0.35, **_pair("mouthUpperUp", 0.15), **_pair("mouthLowerDown", 0.3),
          **_pair("mouthStretch", 0.2)},
    # D [AI]: wide open mouth (AA in "father").
    "D": {"jawOpen": 0.7, **_pair("mouthUpperUp", 0.25), **_pair("mouthLowerDown", 0.4),
          **_pair("mouthStretch", 0.1)},
    # E [O]: slightly rounded mouth (AO in "off", ER in "bird"), no wider open than C.
    "E": {"jawOpen": 0.3, "mouthFunnel": 0.45, "mouthPucker": 0.25, **_pair("mouthLowerDown", 0.1)},
    # F [U]: puckered lips (UW in "you", OW in "show", W in "way").
    "F": {"jawOpen": 0.12, "mouthPucker": 0.75, "mouthFunnel": 0.35},
    # G [FV]: upper teeth on the lower lip (F, V): the lower lip rolls in under the raised upper lip.
    "G": {"jawOpen": 0.08, "mouthRollLower": 0.6, **_pair("mouthUpperUp", 0.3)},
    # H [L]: long L, tongue raised behind the upper teeth; open at least as C, not quite as D.
    "H": {"jawOpen": 0.5, **_pair("mouthUpperUp", 0.15), **_pair("mouthLowerDown", 0.3)},
    # X [rest]: idle, lips closed and relaxed: the neutral face.
    "X": {},
}
NAMES = [n for n in ARKIT_NAMES if any(n in s for s in SHAPES.values())]
_TABLE = np.array([[SHAPES[s].get(n, 0.0) for n in NAMES] for s in SHAPES], np.float64)
_ROW = {s: k for k, s in enumerate(SHAPES)}


def sniff(data: bytes) -> bool:
    """True for Rhubarb's JSON (mouthCues) or TSV (`seconds<TAB>A..H|X` lines)."""
    head = _util.head(data)
    if head[:1] == b"{":
        return b'"mouthCues"' in head
    lines = head.split(b"\n")
    if len(data) > _util.SNIFF_BYTES:
        lines = lines[:-1]  # the cut may split the last line
    lines = [ln for ln in lines[:50] if ln.strip()]
    return bool(lines) and all(_TSV_SNIFF.match(ln) for ln in lines)


def parse(data: bytes, name: str = "rhubarb.json") -> WeightTrack:
    """Rhubarb mouth cues as a WeightTrack of ARKit weights sampled at the file's rate or 60 fps."""
    body = _util.text(data, name, WHAT)
    if body.lstrip()[:1] == "{":
        starts, ends, shapes, fps = _json_cues(_util.json_doc(data, name, WHAT), name)
    else:
        starts, ends, shapes, fps = _tsv_cues(body, name)
    duration = float(ends[-1])
    n = max(1, math.ceil(duration * fps - 1e-6))
    _util.frame_count(n, name)
    times = np.arange(n) / fps
    return WeightTrack(list(NAMES), times, sample(starts, ends, shapes, times).astype(np.float32), fps,
                       source=LAYOUT.name)


def sample(starts: np.ndarray, ends: np.ndarray, shapes: list[str], times: np.ndarray) -> np.ndarray:
    """(T, K) weights of the cues at `times`: the step function averaged over CROSSFADE around each time."""
    # Segments in order: the cues and the gaps between them (rest X, as before a first cue that starts late), the
    # first and last shapes held beyond the ends so the first and last frames are not faded.
    seg_start = [min(starts[0], 0.0) - CROSSFADE]
    seg_rows = [_ROW[shapes[0]] if starts[0] <= 0 else _ROW["X"]]
    for k in range(len(shapes)):
        if k and starts[k] > ends[k - 1]:
            seg_start.append(ends[k - 1])
            seg_rows.append(_ROW["X"])
        seg_start.append(starts[k])
        seg_rows.append(_ROW[shapes[k]])
    seg_start.append(ends[-1])
    seg_rows.append(_ROW[shapes[-1]])
    b = np.array(seg_start, np.float64)
    values = _TABLE[seg_rows]  # (S, K)
    # F(t), the integral of the step function from b[0], is piecewise linear: exact at the breakpoints.
    f_b = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values[:-1] * np.diff(b)[:, None], axis=0)])

    def integral(t: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(b, t, side="right") - 1, 0, len(b) - 1)
        return f_b[i] + values[i] * (t - b[i])[:, None]

    h = CROSSFADE / 2
    return (integral(times + h) - integral(times - h)) / CROSSFADE


def _rate(metadata, name: str) -> float:
    if not isinstance(metadata, dict):
        return DEFAULT_FPS
    value = metadata.get("fps", metadata.get("frameRate"))
    return DEFAULT_FPS if value is None else _util.fps_value(value, name)


def _json_cues(doc, name: str) -> tuple[np.ndarray, np.ndarray, list[str], float]:
    if not isinstance(doc, dict) or not isinstance(doc.get("mouthCues"), list):
        raise InputError(f"{name} is not a Rhubarb Lip Sync JSON: it needs a mouthCues list.")
    cues = doc["mouthCues"]
    if not cues:
        raise InputError(f"{name}: mouthCues is empty; the recording has no cues.")
    _util.frame_count(len(cues), name)
    starts, ends, shapes = [], [], []
    for k, cue in enumerate(cues):
        if not isinstance(cue, dict) or not {"start", "end", "value"} <= cue.keys():
            raise InputError(f"{name}: mouth cue {k} needs start, end and value.")
        starts.append(_util.number(cue["start"], name, f"mouth cue {k} start"))
        ends.append(_util.number(cue["end"], name, f"mouth cue {k} end"))
        shapes.append(_shape(cue["value"], name, f"mouth cue {k}"))
    s, e = np.array(starts), np.array(ends)
    _check_times(s, e, name)
    return s, e, shapes, _rate(doc.get("metadata"), name)


def _tsv_cues(body: str, name: str) -> tuple[np.ndarray, np.ndarray, list[str], float]:
    lines = [(k + 1, ln) for k, ln in enumerate(body.splitlines()) if ln.strip()]
    _util.frame_count(len(lines), name)
    times, shapes = [], []
    for line_no, ln in lines:
        m = TSV_LINE.match(ln)
        if not m:
            raise InputError(f"{name} line {line_no}: {ln.strip()[:30]!r} is not `seconds<TAB>shape`; the file is "
                             f"not a {WHAT}.")
        try:
            t = float(m.group(1))
        except ValueError:
            raise InputError(f"{name} line {line_no}: {m.group(1)[:30]!r} is not a time in seconds.") from None
        if not math.isfinite(t):
            raise InputError(f"{name} line {line_no}: the time is NaN or infinite.")
        times.append(t)
        shapes.append(_shape(m.group(2), name, f"line {line_no}"))
    t = np.array(times)
    if len(t) == 1:  # only the end line: a zero-length recording
        return t, t, shapes, DEFAULT_FPS
    _check_times(t[:-1], t[1:], name)
    return t[:-1], t[1:], shapes[:-1], DEFAULT_FPS


def _shape(value, name: str, where: str) -> str:
    if not isinstance(value, str) or value.strip().upper() not in SHAPES:
        raise InputError(f"{name}: {where} has mouth shape {str(value)[:20]!r}; Rhubarb's shapes are A-H and X.")
    return value.strip().upper()


def _check_times(starts: np.ndarray, ends: np.ndarray, name: str) -> None:
    if starts[0] < 0:
        raise InputError(f"{name}: the first cue starts at {starts[0]} s, before the recording.")
    if np.any(ends < starts):
        k = int(np.argmax(ends < starts))
        raise InputError(f"{name}: cue {k} ends ({ends[k]} s) before it starts ({starts[k]} s).")
    if len(starts) > 1 and np.any(starts[1:] < ends[:-1] - 1e-9):
        k = int(np.argmax(starts[1:] < ends[:-1] - 1e-9)) + 1
        raise InputError(f"{name}: cue {k} starts at {starts[k]} s, before cue {k - 1} ends ({ends[k - 1]} s); "
                         "the cues are out of order.")


LAYOUT = CaptureLayout(
    name="rhubarb",
    label="Rhubarb Lip Sync mouth cues",
    extensions=(".json", ".tsv", ".txt"),
    sniff=sniff,
    parse=parse,
    doc="Rhubarb Lip Sync README, Output formats (JSON mouthCues, TSV) and Mouth shapes (A-H, X)",
)
