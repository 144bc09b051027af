"""Held colour steps, compiled: the greedy behind ``colours.color_steps`` and the colour error it plays.

Each path's frames are sequential (a step ends where a frame no longer fits the colour held), so both loops run
in numba, frame by frame with each path's state held, over the Sheet's colours as stored (float32 (T, N, 3) in
0..1, read through the paths' columns): the loop over frames vectorised over paths it replaced cost a Python
iteration and a (P, 3) gather per frame, a cost that grew with every frame of a long capture.
"""

from __future__ import annotations

import numba
import numpy as np

from converter.encode import parallel


def hold(rgb: np.ndarray, paths: np.ndarray, active: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Key mask (T + 1, P) and held levels (T + 1, P, 3) uint8 of the fewest steps within tolerance levels per
    channel of every shown frame, for the columns paths (P,) of rgb (T, N, 3) shown where active (T, P)."""
    t, p = active.shape
    mask = np.zeros((t + 1, p), bool)
    values = np.zeros((t + 1, p, 3), np.uint8)
    if t and p:
        parallel.threaded(_hold, p, np.ascontiguousarray(rgb), np.ascontiguousarray(paths, np.int64),
                          np.ascontiguousarray(active, bool), float(tolerance), mask, values)
    return mask, values


def played_error(rgb: np.ndarray, paths: np.ndarray, active: np.ndarray, mask: np.ndarray,
                 values: np.ndarray) -> np.ndarray:
    """Per shown (frame, path), path by path, the largest channel error in levels (float32) of the held steps
    (mask, values as ``hold`` gives them; frame 0 a key wherever a path has keys) against rgb's columns paths."""
    t, p = active.shape
    active = np.ascontiguousarray(active, bool)
    counts = active.sum(axis=0)
    out = np.empty(int(counts.sum()), np.float32)
    if t and p:
        parallel.threaded(_error, p, np.ascontiguousarray(rgb), np.ascontiguousarray(paths, np.int64), active,
                          np.ascontiguousarray(mask, bool), np.ascontiguousarray(values), np.cumsum(counts) - counts,
                          out)
    return out


@numba.njit(cache=True, nogil=True)
def _hold(rgb, paths, active, tolerance, mask, values, first, stop):
    """hold() of paths first..stop-1: the arithmetic of the vectorised loop it replaced, frame by frame with
    each path's step in progress held per path (a frame's colours are one row: read path by path over
    thousands of frames, every read was a cache miss)."""
    t = active.shape[0]
    n = stop - first
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    start = np.zeros(n, np.int64)
    x = np.empty(3)
    for f in range(t + 1):
        for k in range(n):
            j = first + k
            if f < t:
                a = active[f, j]
                spread = -np.inf
                for c in range(3):
                    x[c] = np.float64(rgb[f, paths[j], c]) * 255
                    spread = max(spread, max(hi[k, c], x[c]) - min(lo[k, c], x[c]))
                cut = a and spread / 2 + 0.5 > tolerance  # frame f does not fit the held colour
            else:
                a, cut = False, True  # the loop end holds the last step
            if cut:
                s = start[k]
                mask[s, j] = True
                for c in range(3):
                    mid = (lo[k, c] + hi[k, c]) / 2 if np.isfinite(lo[k, c]) else 0.0
                    values[s, j, c] = np.uint8(min(max(np.rint(mid), 0.0), 255.0))
                start[k] = f
                for c in range(3):
                    lo[k, c], hi[k, c] = x[c], x[c]
            elif a:
                for c in range(3):
                    lo[k, c], hi[k, c] = min(lo[k, c], x[c]), max(hi[k, c], x[c])


@numba.njit(cache=True, nogil=True)
def _error(rgb, paths, active, mask, values, at, out, first, stop):
    """played_error() of paths first..stop-1 into out from at[j] on, frame by frame (as _hold)."""
    t = active.shape[0]
    n = stop - first
    held = np.zeros(n, np.int64)
    i = at[first:stop].copy()
    for f in range(t):
        for k in range(n):
            j = first + k
            if mask[f, j]:
                held[k] = f
            if not active[f, j]:
                continue
            err = 0.0
            for c in range(3):
                err = max(err, abs(np.float64(rgb[f, paths[j], c]) * 255 - np.float64(values[held[k], j, c])))
            out[i[k]] = np.float32(err)
            i[k] += 1
