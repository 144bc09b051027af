"""Warm a worker before it takes jobs: one tiny conversion (no GL) compiles or loads the JIT-compiled kernels.

The first call of numba kernels holds the GIL for seconds (longer on a busy machine), which would starve the
lease heartbeat of the first job. Done once per worker process (embedded) or once in the RQ worker's main
process, before it forks work horses, so every horse inherits the warm code.
"""

from __future__ import annotations

import logging

import numpy as np

from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation
from converter.options import ConversionOptions

log = logging.getLogger("facesvg.webapp")


def warm_converter() -> None:
    """Convert a 4-frame tetrahedron to SVG in memory (occlusion off: no GL context is created)."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32)
    frames = np.stack([v + np.float32(0.1 * k) * (v[:, 1:2] > 0) for k in range(4)])
    anim = FaceAnimation(frames, faces, np.zeros(len(faces), np.int32), (Part("skin", (0.8, 0.6, 0.5)),), 10.0,
                         "warmup")
    try:
        convert_animation(anim, ConversionOptions(size=48, occlusion=False))
    except Exception as exc:  # warming is an optimisation; a failure here must not stop the worker
        log.warning("worker warm-up skipped: %s: %s", type(exc).__name__, exc)
