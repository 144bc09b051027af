"""The capture fixtures of tests/data/captures that H1b's layouts read, and bytes of other layouts to sniff against."""

from __future__ import annotations

from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "data" / "captures"
# fixture -> the CaptureLayout.name that must claim it
OWNERS = {
    "rokoko_live_v3.jsonl": "rokoko-json",
    "said_coeffs.csv": "said-csv",
    "azure_visemes.jsonl": "azure-viseme-json",
    "a2f_charlie_cut.json": "audio2face-json",
    "rhubarb_hi.json": "rhubarb",
    "rhubarb_hi.tsv": "rhubarb",
}
# Other layouts' heads, written from their documented layouts: none of H1b's sniffs may claim them.
FOREIGN = {
    "livelinkface.csv": b"Timecode,BlendShapeCount,EyeBlinkLeft,JawOpen\n00:00:01:00.000,2,0.1,0.2\n",
    "columnar.csv": b"time,jawOpen,eyeBlinkLeft\n0.0,0.1,0.0\n",
    "frames.json": b'[{"time": 0.0, "blendshapes": {"jawOpen": 0.1}}]',
    "mediapipe.json": b'[{"timestamp": 1000, "blendshapes": [{"categoryName": "jawOpen", "score": 0.1}]}]',
    "obj.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
}


def read(name: str) -> bytes:
    """The bytes of a fixture in tests/data/captures."""
    return (DATA / name).read_bytes()


def others(layout: str) -> dict[str, bytes]:
    """Every sample H1b's layout `layout` must not claim: the other fixtures and the foreign heads."""
    out = {n: read(n) for n, owner in OWNERS.items() if owner != layout}
    return {**out, **FOREIGN}
