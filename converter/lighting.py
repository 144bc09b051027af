"""The one lighting model shared by the prerender, flat shading and Gouraud shading."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Lighting(NamedTuple):
    """A key light fixed relative to the camera plus ambient light; Lambert diffuse, no specular."""

    direction_eye: tuple[float, float, float] = (-0.35, 0.45, 0.82)  # towards the light, eye space
    diffuse: float = 0.75
    ambient: float = 0.30


DEFAULT_LIGHTING = Lighting()


def light_direction_world(view: np.ndarray, lighting: Lighting = DEFAULT_LIGHTING) -> np.ndarray:
    """Unit vector towards the key light in world space for a camera's view matrix."""
    d = np.asarray(lighting.direction_eye, np.float64)
    d = d / np.linalg.norm(d)
    return view[:3, :3].T @ d


def lambert(
    normals: np.ndarray, base_rgb: np.ndarray, view: np.ndarray, lighting: Lighting = DEFAULT_LIGHTING
) -> np.ndarray:
    """Display-space colour base * (ambient + diffuse * max(0, n.l)), clipped to 0..1; broadcasts."""
    light = light_direction_world(view, lighting).astype(np.float32)
    ndl = np.clip(np.asarray(normals, np.float32) @ light, 0.0, None)
    return np.clip(np.asarray(base_rgb, np.float32) * (lighting.ambient + lighting.diffuse * ndl)[..., None], 0.0, 1.0)
