"""A small synthetic 'captured' head for rigid-factoring tests: a curved skin sheet, one eye in front of it."""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation, Part


def grid(n: int, z0: float, radius: float, curve: float) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid of the disc-ish patch, bulging toward +z, counter-clockwise seen from +z."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    verts = np.stack([radius * u, radius * v, z0 + curve * (1 - u ** 2 - v ** 2)], -1).reshape(-1, 3)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).reshape(-1)
    faces = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return verts, faces.astype(np.int32)


def captured_head(n_frames: int = 60, jitter: float = 1.0, seed: int = 3, n: int = 14) -> FaceAnimation:
    """Skin patch + eye patch: head yaw/roll sway with pose jitter, eye rotation, a local 'mouth' bump."""
    rng = np.random.default_rng(seed)
    skin_v, skin_f = grid(n, 0.0, 5.0, 1.5)
    eye_v, eye_f = grid(5, 1.8, 0.8, 0.3)
    eye_v[:, 0] += 1.5
    eye_v[:, 1] += 1.5
    verts = np.vstack([skin_v, eye_v])
    faces = np.vstack([skin_f, eye_f + len(skin_v)])
    part_ids = np.r_[np.zeros(len(skin_f)), np.ones(len(eye_f))].astype(np.int32)
    k = np.arange(n_frames) / n_frames
    yaw = np.radians(15) * np.sin(2 * np.pi * k) + jitter * np.radians(0.1) * rng.standard_normal(n_frames)
    roll = np.radians(5) * np.sin(4 * np.pi * k) + jitter * np.radians(0.1) * rng.standard_normal(n_frames)
    shift = np.c_[0.8 * np.sin(2 * np.pi * k + 1), 0.4 * np.cos(2 * np.pi * k), np.zeros(n_frames)]
    shift += jitter * 0.01 * rng.standard_normal((n_frames, 3))
    frames = np.repeat(verts[None], n_frames, 0)
    mouth = np.exp(-((verts[:, 0]) ** 2 + (verts[:, 1] + 2.5) ** 2) / 0.8)[None] * np.sin(6 * np.pi * k)[:, None]
    frames[..., 1] -= 0.4 * mouth
    eye = len(skin_v) + np.arange(len(eye_v))
    gaze = np.radians(12) * np.sin(3 * np.pi * k)
    c = np.array([1.5, 1.5, 1.0])
    cg, sg = np.cos(gaze), np.sin(gaze)
    rel = frames[:, eye] - c
    frames[:, eye, 0] = c[0] + cg[:, None] * rel[..., 0] + sg[:, None] * rel[..., 2]
    frames[:, eye, 2] = c[2] - sg[:, None] * rel[..., 0] + cg[:, None] * rel[..., 2]
    cy, sy, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    z, o = np.zeros_like(yaw), np.ones_like(yaw)
    ry = np.stack([np.stack([cy, z, sy], -1), np.stack([z, o, z], -1), np.stack([-sy, z, cy], -1)], 1)
    rz = np.stack([np.stack([cr, -sr, z], -1), np.stack([sr, cr, z], -1), np.stack([z, z, o], -1)], 1)
    frames = np.einsum("tij,tvj->tvi", ry @ rz, frames) + shift[:, None]
    frames += jitter * 0.002 * rng.standard_normal(frames.shape)
    parts = (Part("skin", (0.85, 0.66, 0.55)), Part("eye", (0.95, 0.95, 0.93)))
    return FaceAnimation(frames.astype(np.float32), faces, part_ids, parts, 25.0, "synthetic-capture")
