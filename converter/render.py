"""Offscreen OpenGL through pyrender on Mesa EGL: the prerender (the triangle-id pass is converter.idpass)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np

from converter.camera import Camera
from converter.egl import render_errors


def _pyrender():
    with render_errors(lambda: None):
        import pyrender  # noqa: PLC0415 - imported late so the EGL platform variable is set first
    return pyrender


class _MatrixCamera:
    """A pyrender camera whose projection is exactly our Camera's."""

    def __new__(cls, camera: Camera):
        pyrender = _pyrender()

        class Fixed(pyrender.camera.Camera):
            def get_projection_matrix(self, width=None, height=None):
                return camera.projection.astype(np.float64)

        return Fixed(znear=0.01, zfar=100.0)


@contextmanager
def offscreen(width: int, height: int) -> Iterator[object]:
    """An OffscreenRenderer, deleted afterwards; RenderError names what to install when EGL is missing."""
    pyrender = _pyrender()
    with render_errors(lambda: None):
        renderer = pyrender.OffscreenRenderer(width, height)
    try:
        yield renderer
    finally:
        renderer.delete()


def _scene(camera: Camera):
    pyrender = _pyrender()
    scene = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[0, 0, 0])
    scene.add(_MatrixCamera(camera), pose=np.linalg.inv(camera.view))
    return scene


def _mesh(positions: np.ndarray, faces: np.ndarray, colors: np.ndarray, smooth: bool):
    """A pyrender mesh with per-vertex (smooth) or per-face (flat) RGBA uint8 colours."""
    pyrender = _pyrender()
    import trimesh  # noqa: PLC0415

    if smooth:
        tm = trimesh.Trimesh(positions, faces, vertex_colors=colors, process=False)
    else:
        tm = trimesh.Trimesh(positions, faces, face_colors=colors, process=False)
    return pyrender.Mesh.from_trimesh(tm, smooth=smooth)


def render_frames(
    frames: np.ndarray, faces: np.ndarray, vertex_rgb: np.ndarray, camera: Camera, which: list[int]
) -> dict[int, np.ndarray]:
    """The prerender of chosen frames: GL-interpolated lit vertex colours (Gouraud), (H, W, 4) uint8 RGBA."""
    pyrender = _pyrender()
    out: dict[int, np.ndarray] = {}
    flags = pyrender.RenderFlags.FLAT | pyrender.RenderFlags.RGBA
    with offscreen(camera.width, camera.height) as r:
        for k in which:
            scene = _scene(camera)
            rgba = np.concatenate(
                [np.round(vertex_rgb[k] * 255), np.full((vertex_rgb.shape[1], 1), 255)], axis=1
            ).astype(np.uint8)
            scene.add(_mesh(frames[k], faces, rgba, smooth=True))
            color, _ = r.render(scene, flags=flags)
            out[int(k)] = np.ascontiguousarray(color)
    return out
