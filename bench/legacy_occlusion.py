"""The occlusion pass as it was before converter.idpass (kept only to compare kept sets and cost against).

A new pyrender mesh per frame, pyrender's multisampled colour target with ids packed in RGB, colour and depth
read back, np.unique per frame.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from converter import render
from converter.camera import Camera


def legacy_triangle_ids(frames: np.ndarray, faces: np.ndarray, camera: Camera) -> np.ndarray:
    """Bool (T, F): which triangles cover at least one pixel of each frame's (multisampled) id render."""
    pyrender = render._pyrender()
    t, f = frames.shape[0], faces.shape[0]
    ids = np.arange(1, f + 1, dtype=np.int64)
    rgba = np.stack([ids & 255, (ids >> 8) & 255, (ids >> 16) & 255, np.full(f, 255)], axis=1).astype(np.uint8)
    seen = np.zeros((t, f), bool)
    with render.offscreen(camera.width, camera.height) as r:
        scene = render._scene(camera)
        node = None
        for k in range(t):
            if node is not None:
                scene.remove_node(node)
            node = scene.add(render._mesh(frames[k], faces, rgba, smooth=False))
            color, _ = r.render(scene, flags=pyrender.RenderFlags.FLAT)
            px = color.reshape(-1, 3).astype(np.int64)
            code = px[:, 0] | (px[:, 1] << 8) | (px[:, 2] << 16)
            code = code[(code > 0) & (code <= f)]
            seen[k, np.unique(code) - 1] = True
    return seen
