"""Small animated test subjects for the Gouraud writer: an ellipsoid with two coloured parts, turning."""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation, Part


def ellipsoid(n_frames: int = 3, subdivisions: int = 2, fps: float = 10.0) -> FaceAnimation:
    """An icosphere squashed to an egg, its top in a second part colour, yawing 15 degrees a frame."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(m.vertices, np.float32) * np.array([1.0, 1.2, 0.9], np.float32)
    f = np.asarray(m.faces, np.int32)
    pid = (v[f].mean(1)[:, 1] > 0.35).astype(np.int32)
    frames = []
    for k in range(n_frames):
        a = np.radians(15 * k)
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], np.float32)
        frames.append(v @ r.T)
    parts = (Part("skin", (0.85, 0.66, 0.55)), Part("mouth", (0.55, 0.20, 0.22)))
    return FaceAnimation(np.stack(frames), f, pid, parts, fps, "egg")
