"""Camera: OpenGL view and projection matrices plus a pixel viewport, and the projection of points."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from converter.errors import InputError
from converter.viewport import to_pixels, view_extent

FIT_CHUNK = 1 << 20  # points per chunk when fitting a camera to every vertex of every frame


class Camera(NamedTuple):
    """Right-handed, y up, looking down -z; clip space [-1, 1]^3; viewport in pixels, y down in images."""

    view: np.ndarray  # (4, 4) world -> eye
    projection: np.ndarray  # (4, 4) eye -> clip
    width: int
    height: int
    ortho: bool = False

    @staticmethod
    def fit(
        frames: np.ndarray,
        size: int = 512,
        yaw: float = 0.0,
        pitch: float = 0.0,
        fov: float = 30.0,
        ortho: bool = False,
        margin: float = 0.04,
    ) -> Camera:
        """A camera that frames every vertex of every frame, seen from yaw/pitch degrees off the front (+z)."""
        if not (16 <= size <= 8192):
            raise InputError(f"size must be between 16 and 8192 pixels, got {size}.")
        if not (1.0 <= fov <= 150.0):
            raise InputError(f"fov must be between 1 and 150 degrees, got {fov}.")
        pts = np.asarray(frames).reshape(-1, 3)

        def chunks():  # float64 copies one chunk at a time: a long clip has millions of points
            return (np.asarray(pts[s:s + FIT_CHUNK], np.float64) for s in range(0, len(pts), FIT_CHUNK))

        lo, hi = _extent(pts)
        center = (lo + hi) / 2
        radius = float(np.linalg.norm(hi - lo) / 2) or 1.0
        y, p = math.radians(yaw), math.radians(pitch)
        direction = np.array([math.sin(y) * math.cos(p), math.sin(p), math.cos(y) * math.cos(p)])
        distance = radius / math.sin(math.radians(fov) / 2) * 1.05
        view = look_at(center + direction * distance, center, np.array([0.0, 1.0, 0.0]))
        ext = np.full((2, 3), np.inf)  # row 0: minima, row 1: negated maxima of (depth, x, y)
        for c in chunks():
            lo_hi = view_extent(c @ view[:3, :3].T, view[:3, 3], ortho)
            ext = np.minimum(ext, np.stack([lo_hi[0], -lo_hi[1]]))
        (d_lo, x_lo, y_lo), (d_hi, x_hi, y_hi) = ext[0], -ext[1]
        near = max(float(d_lo) * 0.5, 1e-4 * distance)
        far = float(d_hi) * 1.5 + 1e-6
        cx, cy = (x_lo + x_hi) / 2, (y_lo + y_hi) / 2
        half = max(x_hi - x_lo, y_hi - y_lo) / 2 * (1 + 2 * margin) or 1.0
        if ortho:
            proj = orthographic(cx - half, cx + half, cy - half, cy + half, near, far)
        else:
            proj = frustum((cx - half) * near, (cx + half) * near, (cy - half) * near, (cy + half) * near, near, far)
        return Camera(view.astype(np.float64), proj.astype(np.float64), int(size), int(size), bool(ortho))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel xy (..., 2) with y down, NDC depth (...), and clip w (...) of world points (..., 3)."""
        m = self.projection @ self.view
        p = np.asarray(points, np.float64)
        return to_pixels(p @ m[:3, :3].T, p @ m[3, :3], m[:3, 3], m[3, 3], self.width, self.height)

    def eye_position(self) -> np.ndarray:
        """The camera's position in world space."""
        inv = np.linalg.inv(self.view)
        return inv[:3, 3]

    def to_json(self) -> dict:
        """Row-major matrices and viewport, as the SVG metadata carries them."""
        return {
            "view": [[float(x) for x in row] for row in self.view],
            "projection": [[float(x) for x in row] for row in self.projection],
            "viewport": [self.width, self.height],
            "ortho": self.ortho,
        }

    @staticmethod
    def from_json(data: dict) -> Camera:
        """Inverse of to_json."""
        return Camera(
            np.array(data["view"], np.float64),
            np.array(data["projection"], np.float64),
            int(data["viewport"][0]),
            int(data["viewport"][1]),
            bool(data.get("ortho", False)),
        )


def _extent(pts: np.ndarray, rows: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Per column minimum and maximum (float64) of points pts (N, 3), exact, without float64 copies.

    Reduced as (N / rows, 3 rows) blocks: numpy reduces an (N, 3) array along axis 0 three values at a time,
    far slower on a long clip's hundred million points."""
    head = len(pts) - len(pts) % rows
    parts = [pts[head:]] if head < len(pts) else []
    if head:
        wide = pts[:head].reshape(-1, 3 * rows)
        parts += [wide.min(axis=0).reshape(rows, 3), wide.max(axis=0).reshape(rows, 3)]
    both = np.concatenate(parts)
    return both.min(axis=0).astype(np.float64), both.max(axis=0).astype(np.float64)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The view matrix of a camera at eye looking at target (gluLookAt)."""
    f = target - eye
    f = f / np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking straight up or down: pick another up
        s = np.cross(f, np.array([0.0, 0.0, -1.0]))
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """glFrustum: an off-centre perspective projection."""
    m = np.zeros((4, 4))
    m[0, 0] = 2 * near / (right - left)
    m[1, 1] = 2 * near / (top - bottom)
    m[0, 2] = (right + left) / (right - left)
    m[1, 2] = (top + bottom) / (top - bottom)
    m[2, 2] = -(far + near) / (far - near)
    m[2, 3] = -2 * far * near / (far - near)
    m[3, 2] = -1
    return m


def orthographic(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """glOrtho: an orthographic projection."""
    m = np.eye(4)
    m[0, 0] = 2 / (right - left)
    m[1, 1] = 2 / (top - bottom)
    m[2, 2] = -2 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m
