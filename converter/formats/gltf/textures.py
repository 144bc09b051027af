"""Base-colour textures sampled at the vertices: images decoded with Pillow, bilinear lookups with scipy.ndimage.

The sampled colours are the texture's own sRGB-encoded values; the scene decodes them to linear, multiplies the
baseColorFactor (glTF 2.0) and makes them the primitive's vertex colours, so the flat and Gouraud outputs keep
eyes, brows and lips painted in a texture. KHR_texture_transform is not applied.
"""

from __future__ import annotations

import io
import warnings

import numpy as np
from PIL import Image, UnidentifiedImageError

from converter.srgb import srgb_to_linear

MAX_TEXTURE_PIXELS = 1 << 26  # a 8192 x 8192 texture; larger ones are not decoded
# glTF sampler wrap modes -> scipy.ndimage boundary modes (REPEAT is the default).
WRAP_MODES = {33071: "nearest", 33648: "grid-mirror", 10497: "grid-wrap"}


def decode_image(data: bytes) -> np.ndarray | None:
    """(H, W, 3) uint8 pixels of a PNG/JPEG/WebP/... image, or None when Pillow cannot decode it (e.g. KTX2)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as image:
                if image.width * image.height > MAX_TEXTURE_PIXELS:
                    return None
                return np.asarray(image.convert("RGB"))
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, Image.DecompressionBombError,
            Image.DecompressionBombWarning):
        return None


def sample_texture(pixels: np.ndarray, uv: np.ndarray, wrap_s: int = 10497, wrap_t: int = 10497,
                   decode_srgb: bool = False) -> np.ndarray:
    """(V, 3) float32 colours 0..1 of pixels (H, W, 3) at texture coordinates uv (V, 2), bilinear, glTF wrap modes.

    decode_srgb: decode the texels to linear light before filtering (as a GPU filters an sRGB texture)."""
    h, w = pixels.shape[:2]
    # glTF UV (0, 0) is the image's top-left corner; pixel centres sit at half-integers.
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    mode_s, mode_t = WRAP_MODES.get(wrap_s, "grid-wrap"), WRAP_MODES.get(wrap_t, "grid-wrap")
    mode = mode_s
    if mode_s != mode_t:  # map_coordinates takes one mode: fold each axis into the image first
        x, y, mode = _wrap(x, w, mode_s), _wrap(y, h, mode_t), "nearest"
    from scipy import ndimage  # noqa: PLC0415 - slow to import (it parses docstrings); only textured files need it

    out = np.empty((len(uv), 3), np.float32)
    lut = (srgb_to_linear if decode_srgb else np.asarray)(np.arange(256, dtype=np.float32) / 255.0)
    for c in range(3):  # one channel at a time: a float copy of a large texture is 4 bytes a texel
        out[:, c] = ndimage.map_coordinates(lut[pixels[..., c]], [y, x], order=1, mode=mode, output=np.float32)
    return np.clip(out, 0.0, 1.0)


def _wrap(coord: np.ndarray, size: int, mode: str) -> np.ndarray:
    """Pixel coordinates folded into [-0.5, size - 0.5] as the wrap mode repeats, mirrors or clamps the image."""
    if mode == "grid-wrap":
        return np.mod(coord + 0.5, size) - 0.5
    if mode == "grid-mirror":
        period = np.mod(coord + 0.5, 2 * size)
        return np.where(period < size, period, 2 * size - period) - 0.5
    return np.clip(coord, 0.0, size - 1.0)
