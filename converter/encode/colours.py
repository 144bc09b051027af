"""Each path's own colour track, within a colour tolerance: linear keys (the player) or held steps (the exact SVG).

The shared alternative, one animated colour for many paths, is converter.encode.palette.
"""

from __future__ import annotations

import numpy as np

from converter.encode import freeknots
from converter.encode import keys as keyframes
from converter.encode import steps as held

COLOR_TIME_LEVELS = 0.1  # of which rounding the colour keyTimes may take


def color_keys(rgb: np.ndarray, active: np.ndarray, tolerance: float) -> keyframes.Keys:
    """Colour (T, P, 3) in 0..1 as linear keys within tolerance 8-bit levels per channel where shown (values
    rounded to integer levels, which the tolerance includes; uint8). A path whose shown colours all lie within
    the tolerance of their mid-range is one static colour (two equal keys). Worked out a block of paths at a
    time (each path's keys are its own), so only the keys take memory for every path."""
    t, p = active.shape
    mask = np.zeros((t + 1, p), bool)
    values = np.zeros((t + 1, p, 3), np.uint8)
    size = freeknots.block_tracks(t)
    for a in range(0, p, size):
        sl = slice(a, a + size)
        mask[:, sl], values[:, sl] = _color_block(np.asarray(rgb[:, sl], np.float64) * 255, active[:, sl], tolerance)
    return keyframes.Keys(mask, values, np.where(active.any(axis=0), np.argmax(active, axis=0), -1))


def _color_block(levels: np.ndarray, active: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """color_keys' mask (T+1, N) and values (T+1, N, 3) for colour levels (T, N, 3) in 0..255."""
    t, p = active.shape
    shown = active[..., None]
    lo = levels.min(axis=0, where=shown, initial=np.inf)
    hi = levels.max(axis=0, where=shown, initial=-np.inf)
    flat = ((hi - lo).max(axis=-1, initial=0.0) / 2 + 0.5 <= tolerance) & active.any(axis=0)
    mask = np.zeros((t + 1, p), bool)
    values = np.zeros((t + 1, p, 3))
    mask[[0, t]] = flat
    values[[0, t]] = np.where(flat[:, None], np.rint((lo + hi) / 2), 0.0)
    rest = np.flatnonzero(~flat)
    if len(rest):
        eps = max(tolerance - 0.5 - COLOR_TIME_LEVELS, 1e-6)  # rounding, keyTimes
        keys = freeknots.reduce_free(np.take(levels, rest, axis=1), np.take(active, rest, axis=1), eps)
        mask[:, rest] = keys.mask
        values[:, rest] = np.rint(keys.values)
        # A free key may lie outside 0..255 (extrapolated across hidden frames), where clipping would move the
        # shown frames of its segment: those paths take keys on sampled values, or else every frame.
        for fallback in (lambda c: keyframes.reduce(levels[:, c], active[:, c], eps), None):
            clipped = np.flatnonzero((mask[..., None] & ((values < 0) | (values > 255))).any(axis=(0, 2)))
            if not len(clipped):
                break
            if fallback is None:
                mask[:, clipped] = True
                values[:t, clipped] = np.rint(levels[:, clipped])
                values[t, clipped] = values[t - 1, clipped]
            else:
                keys = fallback(clipped)
                mask[:, clipped], values[:, clipped] = keys.mask, np.rint(keys.values)
    return mask, np.clip(values, 0, 255).astype(np.uint8)


def color_steps(rgb: np.ndarray, active: np.ndarray, tolerance: float,
                paths: np.ndarray | None = None) -> keyframes.Keys:
    """Colour (T, P, 3) in 0..1 (or its columns paths of a wider (T, N, 3)) as steps for a discrete animation:
    per path the fewest held colours (integer levels, uint8) within tolerance levels per channel of every shown
    frame, each held from its first frame (a key; frame 0 always is one, hidden frames take whatever is held).
    Greedy, which is optimal for a max-norm bound on a piecewise-constant fit. A path with one key is one static
    colour.

    Why steps and not linear keys: Chromium re-evaluates an interpolated colour animation far more slowly than a
    discrete one (bench_playback: the sample's exact-colour file played much faster with the same values held), and
    the steps need about as many keys as the linear greedy within the same tolerance."""
    p = active.shape[1]
    mask, values = held.hold(rgb, np.arange(p) if paths is None else paths, active, tolerance)
    return keyframes.Keys(mask, values, np.where(active.any(axis=0), np.argmax(active, axis=0), -1))


def color_error(rgb: np.ndarray, active: np.ndarray, steps: keyframes.Keys,
                paths: np.ndarray | None = None) -> np.ndarray:
    """Per shown (frame, path) the largest channel error in levels (float32) of the played colour (color_steps'
    held values) against the exact shade rgb (T, P, 3) in 0..1 (or its columns paths), path by path."""
    p = active.shape[1]
    return held.played_error(rgb, np.arange(p) if paths is None else paths, active, steps.mask, steps.values)
