"""The sRGB transfer curve (IEC 61966-2-1): display values to linear light and back.

Its own module, numpy only, so that loaders (glTF colours and textures are sRGB-encoded) and the lighting model
share it without a loader importing extraction.
"""

from __future__ import annotations

import numpy as np


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values 0..1 to linear light (IEC 61966-2-1 piecewise curve), float32."""
    c = np.clip(np.asarray(c, np.float32), 0.0, 1.0)
    f = np.float32
    return np.where(c <= 0.04045, c / f(12.92), ((c + f(0.055)) / f(1.055)) ** f(2.4)).astype(np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear light 0..1 to sRGB-encoded values (IEC 61966-2-1 piecewise curve), float32."""
    return encode_clipped(np.clip(np.asarray(c, np.float32), 0.0, 1.0))


def encode_clipped(c: np.ndarray) -> np.ndarray:
    """linear_to_srgb of float32 c already within 0..1 (NaN passes through), with no temporary but the result:
    shading a long capture of the ICT head encodes hundreds of millions of values, where np.where's two full
    branches added much CPU to the power's own."""
    f = np.float32
    c = np.asarray(c)
    out = np.power(c, f(1 / 2.4), out=np.empty(c.shape, np.float32))
    out *= f(1.055)
    out -= f(0.055)
    np.multiply(c, f(12.92), out=out, where=c <= f(0.0031308))
    np.copyto(out, f(1.0), where=c >= 1.0)  # float32 rounding must not dim white
    return out
