"""Benchmark faces built from the ICT FaceKit head in ../shared/data (deterministic; nothing cached in the repo).

    from bench.faces import ict_bench_face, chapter_face
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from converter.animation import FaceAnimation
from converter.formats.ictfacekit import PART_ORDER, IctHead, load_ict_head
from samples.ict_region import NARROW_FACE_VERTICES, Piece, face_region

ICT_FOLDER = ROOT.parent / "shared" / "data" / "ict_facekit"
HEAD_PIVOT = np.array([0.0, -6.0, 0.0])  # the neck, in ICT cm
# Expression, weight-curve period (s), phase (rad): incommensurate periods give varied, smooth combinations.
EXPRESSIONS = (
    ("jawOpen", 3.1, 0.0), ("mouthSmile_L", 4.3, 1.0), ("mouthSmile_R", 4.7, 1.3), ("eyeBlink_L", 2.9, 2.0),
    ("eyeBlink_R", 2.9, 2.05), ("browInnerUp_L", 5.3, 0.4), ("browInnerUp_R", 5.3, 0.5), ("mouthPucker", 3.7, 2.7),
    ("mouthFunnel", 6.1, 4.0), ("cheekPuff_L", 7.3, 3.3),
)

_HEAD: dict[Path, IctHead] = {}


def ict_head(folder: Path = ICT_FOLDER) -> IctHead:
    """The ICT head, read once per process."""
    if folder not in _HEAD:
        _HEAD[folder] = load_ict_head(folder)
    return _HEAD[folder]


def ict_bench_face(n_frames: int = 330, fps: float = 30.0, triangles: int = 6000) -> FaceAnimation:
    """The ICT face region (skin, eyes, teeth, mouth) at ~triangles, with varied expressions and head rotation."""
    return _animated_face(face_region(ict_head(), triangles), n_frames, fps, yaw_deg=15.0, pitch_deg=10.0,
                          name="ict_bench_face")


def chapter_face(n_frames: int = 207, fps: float = 25.0) -> FaceAnimation:
    """A ~484-triangle face, 8.28 s at 25 fps: the size of the chapter's mobile faces (Table 12.5)."""
    # The narrow face (no ears, neck) with skin and eyes only: the low-poly budget goes to the expressive part.
    pieces = face_region(ict_head(), 484, lock_border=False, parts=("skin", "eye", "iris"),
                         face_vertices=NARROW_FACE_VERTICES)
    return _animated_face(pieces, n_frames, fps, yaw_deg=10.0, pitch_deg=5.0, name="chapter_face")


def _animated_face(pieces: list[Piece], n_frames: int, fps: float, yaw_deg: float, pitch_deg: float,
                   name: str) -> FaceAnimation:
    head = ict_head()
    ids = np.concatenate([p.ids for p in pieces])
    offsets = np.cumsum([0] + [len(p.ids) for p in pieces])
    faces = np.concatenate([p.faces + o for p, o in zip(pieces, offsets)])
    part_ids = np.concatenate([np.full(len(p.faces), PART_ORDER.index(p.part), np.int32) for p in pieces])
    rest = head.vertices[ids].astype(np.float64)
    deltas = np.stack([head.delta(e)[ids] for e, _, _ in EXPRESSIONS])  # (K, V, 3)
    t = np.arange(n_frames) / fps
    period = np.array([p for _, p, _ in EXPRESSIONS])
    phase = np.array([ph for _, _, ph in EXPRESSIONS])
    weights = (0.5 - 0.5 * np.cos(2 * np.pi * t[:, None] / period + phase)) ** 2  # smooth, in [0, 1]
    local = rest[None] + np.einsum("tk,kvc->tvc", weights, deltas)
    yaw = np.radians(yaw_deg) * np.sin(2 * np.pi * t / 5.5)
    pitch = np.radians(pitch_deg) * np.sin(2 * np.pi * t / 3.7 + 1.0)
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    zero, one = np.zeros_like(t), np.ones_like(t)
    ry = np.stack([np.stack([cy, zero, sy], -1), np.stack([zero, one, zero], -1), np.stack([-sy, zero, cy], -1)], 1)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cp, -sp], -1), np.stack([zero, sp, cp], -1)], 1)
    rot = ry @ rx  # (T, 3, 3)
    frames = (local - HEAD_PIVOT) @ np.swapaxes(rot, 1, 2) + HEAD_PIVOT
    used = sorted(set(part_ids.tolist()))
    remap = np.zeros(len(PART_ORDER), np.int32)
    remap[used] = np.arange(len(used))
    return FaceAnimation(frames.astype(np.float32), faces, remap[part_ids], tuple(head.parts[i] for i in used), fps,
                         name, extras={"morph_targets": [e for e, _, _ in EXPRESSIONS], "source": "ICT FaceKit"})
