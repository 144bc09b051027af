"""The registry of capture layouts: which files of per-frame ARKit weights facesvg reads, recognised by content.

A capture is what a face-tracking or speech-animation tool records: blendshape weights over time, sometimes with
head and eye angles. Each layout is one module in this package with a `LAYOUT = CaptureLayout(...)` (how to
recognise its bytes, how to read them into a WeightTrack). LAYOUTS lists them; the CLI (`facesvg info`), the
web form's accept list and the mesh loader's "this is a capture" message all read it. A new layout is one module
plus one entry here.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from converter.errors import InputError
from converter.formats.captures import (
    _util,
    audio2face,
    azure,
    columnar,
    facecap,
    framesjson,
    ifacialmocap,
    livelinkface,
    mediapipe,
    rhubarb,
    rokoko,
    said,
)
from converter.formats.captures.base import CaptureLayout, WeightTrack
from converter.userfiles import read_bytes

# Most specific first: each sniff is tried in order and the first that answers True reads the file. The text
# layouts test their first line's shape; the JSON ones their keys, with the generic frame list last.
LAYOUTS: tuple[CaptureLayout, ...] = (
    livelinkface.LAYOUT,
    said.LAYOUT,
    facecap.LAYOUT,
    ifacialmocap.LAYOUT,
    rhubarb.LAYOUT,
    audio2face.LAYOUT,
    columnar.LAYOUT,
    rokoko.LAYOUT,
    azure.LAYOUT,
    mediapipe.LAYOUT,
    framesjson.LAYOUT,
)

# What the mesh loader calls a capture a user gave as the face ("this is <description>, not a face").
DESCRIPTIONS = {
    "livelinkface-csv": "a Live Link Face capture CSV",
    "audio2face-json": "an Audio2Face blendshape weight export",
    "frames-json": "an ARKit blendshape weight capture",
}


def layout_named(name: str) -> CaptureLayout:
    """The registered layout of that name; InputError naming the layouts otherwise."""
    for layout in LAYOUTS:
        if layout.name == name:
            return layout
    raise InputError(f"unknown capture layout {name!r}; the layouts are {', '.join(lt.name for lt in LAYOUTS)}.")


_GLTF_KEYS = re.compile(rb'"(accessors|meshes|buffers|bufferViews|nodes|scenes)"\s*:')


def is_gltf_json(data: bytes) -> bool:
    """A glTF document (binary, or JSON with "asset" and a glTF top-level key): never a capture, whatever keys
    ("weights", "time") its meshes and animations share with capture layouts."""
    if data[:4] == b"glTF":
        return True
    head = data[:_util.SNIFF_BYTES].removeprefix(b"\xef\xbb\xbf").lstrip()
    return head[:1] == b"{" and b'"asset"' in head and bool(_GLTF_KEYS.search(head))


def detect(data: bytes) -> CaptureLayout | None:
    """The first layout whose sniff recognises the bytes, or None (a glTF document is never a capture)."""
    if is_gltf_json(data):
        return None
    return next((layout for layout in LAYOUTS if layout.sniff(data)), None)


def detect_file(path: str | Path) -> CaptureLayout | None:
    """The layout of the file at path from its first bytes, or None (also when it cannot be read)."""
    try:
        with open(path, "rb") as fh:
            return detect(fh.read(_util.SNIFF_BYTES))
    except OSError:
        return None


def labels() -> str:
    """The layouts' labels as one comma-separated list, for messages and help."""
    return ", ".join(layout.label for layout in LAYOUTS)


def parse_capture(data: bytes, name: str = "capture") -> WeightTrack:
    """A WeightTrack from a capture's bytes, its layout recognised by content; name is the user's file name."""
    if not data.strip():
        raise InputError(f"{name} is empty; give a weight capture ({labels()}).")
    layout = detect(data)
    if layout is not None:
        return layout.parse(data, name)
    head = _util.head(data)
    if head[:1] in (b"{", b"["):
        try:
            json.loads(data.decode("utf-8-sig"))
        except UnicodeDecodeError:
            pass
        except (json.JSONDecodeError, RecursionError) as exc:
            raise InputError(f"{name} is not valid JSON ({str(exc)[:60]}); the capture is truncated or "
                             "edited.") from None
    raise InputError(f"{name} is not a weight layout facesvg knows; it reads {labels()}.")


def read_capture(path: str | Path) -> WeightTrack:
    """Read a weight capture file (any layout in LAYOUTS) into a WeightTrack."""
    path = Path(path)
    return parse_capture(read_bytes(path, "weights file"), path.name)


def is_capture(data: bytes) -> str | None:
    """A short description when the bytes are a capture (so a mesh loader can say so), else None."""
    layout = detect(data)
    if layout is None:
        return None
    if layout.name in DESCRIPTIONS:
        return DESCRIPTIONS[layout.name]
    article = "an" if layout.label[:1].lower() in "aeiou" else "a"
    return f"{article} {layout.label} capture"


def extensions() -> tuple[str, ...]:
    """Every layout's file suffixes, sorted and unique (the web form's accept list)."""
    return tuple(sorted({ext.lower() for layout in LAYOUTS for ext in layout.extensions}))


def describe(track: WeightTrack) -> dict:
    """What `facesvg info` says about a capture: layout, frames, rate, duration, names, angles, start timecode."""
    label = next((layout.label for layout in LAYOUTS if layout.name == track.source), track.source or "unknown")

    def moving(angles: np.ndarray | None) -> bool:
        return angles is not None and bool(np.abs(angles).max() > 0)

    return {
        "layout": label,
        "source": track.source,
        "frames": track.n_frames,
        "fps": round(float(track.fps), 4),
        "duration": round(track.duration, 4),
        "regular": track.is_regular(tol=0.5),  # as the drive step judges it: played one row a frame
        "names": len(track.names),
        "first_names": track.names[:5],
        "head_rotation": moving(track.head),
        "eye_rotation": moving(track.eye_left) or moving(track.eye_right),
        "start_timecode": track.start_timecode,
    }
