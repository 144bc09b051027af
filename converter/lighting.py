"""The one lighting model shared by the prerender, flat shading and Gouraud shading, and the sRGB transfer curve.

Colours in a FaceAnimation are display (sRGB-encoded) values (see converter/animation.py); light adds up in
linear light, so lambert decodes the base colour, lights it and encodes the result once, as a glTF viewer does.
"""

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


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values 0..1 to linear light (IEC 61966-2-1 piecewise curve), float32."""
    c = np.clip(np.asarray(c, np.float32), 0.0, 1.0)
    f = np.float32
    return np.where(c <= 0.04045, c / f(12.92), ((c + f(0.055)) / f(1.055)) ** f(2.4)).astype(np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear light 0..1 to sRGB-encoded values (IEC 61966-2-1 piecewise curve), float32."""
    return _encode(np.clip(np.asarray(c, np.float32), 0.0, 1.0))


def _encode(c: np.ndarray) -> np.ndarray:
    """linear_to_srgb of float32 c already within 0..1 (NaN passes through), with no temporary but the result:
    shading a 4,000-frame capture of the ICT head encodes 612 M values, where np.where's two full branches cost a
    third more CPU than the power alone."""
    f = np.float32
    c = np.asarray(c)
    out = np.power(c, f(1 / 2.4), out=np.empty(c.shape, np.float32))
    out *= f(1.055)
    out -= f(0.055)
    np.multiply(c, f(12.92), out=out, where=c <= f(0.0031308))
    np.copyto(out, f(1.0), where=c >= 1.0)  # float32 rounding must not dim white
    return out


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
    return _encode(np.clip(lit, 0.0, 1.0, out=lit))
