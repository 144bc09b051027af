"""The one lighting model shared by the prerender, flat shading and Gouraud shading.

Colours in a FaceAnimation are display (sRGB-encoded) values (see converter/animation.py); light adds up in
linear light, so lambert decodes the base colour, lights it and encodes the result once, as a glTF viewer does.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from converter.srgb import encode_clipped, linear_to_srgb, srgb_to_linear  # noqa: F401  (re-exported)


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
    """Display colour of display base_rgb lit in linear light: srgb(linear(base) * (ambient + diffuse * n.l+))."""
    return lambert_linear(normals, srgb_to_linear(base_rgb), view, lighting)


def lambert_linear(
    normals: np.ndarray, linear_rgb: np.ndarray, view: np.ndarray, lighting: Lighting = DEFAULT_LIGHTING,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """lambert of a base colour already decoded (srgb_to_linear): a block of frames of one mesh decodes it once.
    rows: only these of the normals (..., N, 3) are lit, linear_rgb holding their colours; n.l is still worked out
    for every normal, then taken, so each value has the bits it has among all (BLAS's sums may depend on the row
    count)."""
    light = light_direction_world(view, lighting).astype(np.float32)
    gain = np.asarray(np.asarray(normals, np.float32) @ light)  # an array even for one normal
    if rows is not None:
        gain = np.take(gain, rows, axis=-1)
    np.maximum(gain, 0.0, out=gain)  # n.l+, NaN kept (np.clip's semantics)
    gain *= lighting.diffuse
    gain += lighting.ambient
    lit = linear_rgb * gain[..., None]
    return encode_clipped(np.clip(lit, 0.0, 1.0, out=lit))
