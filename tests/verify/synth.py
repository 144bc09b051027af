"""Synthetic worst cases for the encoder and the verifier: fast jumpy motion, visibility flicker."""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation, Part


def grid(n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n quad grid facing +z (counter-clockwise seen from +z): vertices (V, 3), faces (F, 3)."""
    xs, ys = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 2, i.ravel() + n + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, faces.astype(np.int32)


def fast_motion(n_frames: int = 30, seed: int = 1) -> FaceAnimation:
    """Every vertex swings fast and jumps every few frames (tens of pixels per frame)."""
    rng = np.random.default_rng(seed)
    v, faces = grid(6)
    t = np.arange(n_frames)[:, None, None]
    phase = rng.uniform(0, 2 * np.pi, (1, len(v), 3))
    swing = 0.15 * np.sin(0.9 * t + phase) * np.array([1, 1, 0.2])
    jumps = np.cumsum(rng.normal(0, 0.12, (n_frames, 1, 3)) * (np.arange(n_frames) % 5 == 0)[:, None, None], axis=0)
    frames = v[None] + swing + jumps * np.array([1, 1, 0])
    return FaceAnimation(frames.astype(np.float32), faces, np.zeros(len(faces), np.int32),
                         (Part("skin", (0.8, 0.6, 0.5)),), 25.0, "fast")


def flicker(n_frames: int = 30, seed: int = 2) -> FaceAnimation:
    """Separate triangles spinning about their own vertical axis: facing (and visibility) flips every frame or two."""
    rng = np.random.default_rng(seed)
    n = 40
    centers = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-0.2, 0.2, n)], 1)
    local = np.array([[-0.1, -0.08, 0], [0.1, -0.08, 0], [0.0, 0.1, 0]])
    speed = rng.uniform(1.5, 3.5, n) * rng.choice([-1, 1], n)
    ang = np.arange(n_frames)[:, None] * speed[None] + rng.uniform(0, 6, n)[None]
    c, s = np.cos(ang), np.sin(ang)
    x = local[None, None, :, 0] * c[..., None]
    z = -local[None, None, :, 0] * s[..., None]
    y = np.broadcast_to(local[None, None, :, 1], x.shape)
    frames = centers[None, :, None] + np.stack([x, y, z], -1)  # (T, n, 3, 3)
    faces = np.arange(3 * n, dtype=np.int32).reshape(n, 3)
    return FaceAnimation(frames.reshape(n_frames, 3 * n, 3).astype(np.float32), faces, np.zeros(n, np.int32),
                         (Part("skin", (0.8, 0.6, 0.5)),), 25.0, "flicker")
