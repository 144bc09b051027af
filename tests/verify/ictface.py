"""A small ICT FaceKit-derived animation for tests: the front of the head, expressions and a head turn."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from converter.animation import FaceAnimation

ICT = Path(__file__).resolve().parents[3] / "shared" / "data" / "ict_facekit"
EXPRESSIONS = ("jawOpen", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L", "eyeBlink_R", "browInnerUp_L")


@lru_cache(maxsize=4)
def ict_face(n_frames: int = 40, fps: float = 25.0, turn: float = 20.0, front: float = 0.0,
             stride: int = 1) -> FaceAnimation:
    """Front of the ICT head (centroid z > front cm) with every n-th triangle, expressions and a yaw/pitch sway."""
    from converter.formats.ictfacekit import load_ict_head

    head = load_ict_head(ICT)
    v = head.vertices.astype(np.float64)
    keep = v[head.faces].mean(axis=1)[:, 2] > front
    keep &= np.arange(len(head.faces)) % stride == 0
    faces = head.faces[keep]
    used, inv = np.unique(faces, return_inverse=True)
    faces = inv.reshape(-1, 3).astype(np.int32)
    base = v[used]
    deltas = np.stack([head.delta(n)[used] for n in EXPRESSIONS])
    k = np.arange(n_frames) / max(n_frames - 1, 1)
    w = np.stack([
        np.clip(np.sin(2 * np.pi * k), 0, 1),  # jaw opens then closes
        0.7 * np.sin(np.pi * k) ** 2, 0.7 * np.sin(np.pi * k) ** 2,
        (np.abs(k - 0.5) < 0.06).astype(float),  # a blink mid-way
        (np.abs(k - 0.5) < 0.06).astype(float),
        0.8 * np.clip(np.sin(3 * np.pi * k), 0, 1),
    ], axis=1)
    frames = base[None] + np.einsum("te,evc->tvc", w, deltas)
    yaw = np.radians(turn) * np.sin(2 * np.pi * k)
    pitch = np.radians(turn / 4) * np.sin(4 * np.pi * k)
    pivot = np.array([0.0, base[:, 1].min(), base[:, 2].mean()])
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    ry = np.zeros((n_frames, 3, 3))
    ry[:, 0, 0], ry[:, 0, 2], ry[:, 1, 1], ry[:, 2, 0], ry[:, 2, 2] = cy, sy, 1, -sy, cy
    rx = np.zeros((n_frames, 3, 3))
    rx[:, 0, 0], rx[:, 1, 1], rx[:, 1, 2], rx[:, 2, 1], rx[:, 2, 2] = 1, cp, -sp, sp, cp
    rot = rx @ ry
    frames = np.einsum("tij,tvj->tvi", rot, frames - pivot) + pivot
    return FaceAnimation(frames.astype(np.float32), faces, head.part_ids[keep], head.parts, fps, "ict-face")
