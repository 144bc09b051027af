"""Array helpers for what numpy does slowly at our sizes."""

from __future__ import annotations

import numpy as np


def unique_ints(x: np.ndarray) -> np.ndarray:
    """np.unique of integers x (sorted distinct values, flattened) by one sort. Since numpy 2.3 np.unique finds the
    distinct values with a hash table, which on millions of distinct int64 is far slower than sorting (the
    drawing-order pairs of the 128k-triangle bench face). The sort is numpy's stable one: as fast on shuffled
    integers, and linear on a few sorted runs (those pairs arrive sorted, with each band's chain after them)."""
    s = np.sort(np.asarray(x).ravel(), kind="stable")
    if not len(s):
        return s
    keep = np.empty(len(s), bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def lexsort_ints(keys: tuple[np.ndarray, ...]) -> np.ndarray:
    """np.lexsort(keys) of integer (or bool) keys (the last key primary): one stable argsort of the keys packed
    into an int64, each offset by its least value, where their ranges fit 63 bits together (else np.lexsort).
    The same order, faster on the millions of keys of a long capture."""
    keys = tuple(np.asarray(k) for k in keys)
    if not len(keys[0]):
        return np.zeros(0, np.intp)
    spans = [(int(k.min()), int(k.max())) for k in keys]
    bits = [max(hi - lo, 0).bit_length() for lo, hi in spans]
    if sum(bits) > 63:
        return np.lexsort(keys)
    packed = np.zeros(len(keys[0]), np.int64)
    shift = 0
    for k, (lo, _), b in zip(keys, spans, bits):
        packed |= (k.astype(np.int64) - lo) << shift
        shift += b
    return np.argsort(packed, kind="stable")


def lengths(v: np.ndarray) -> np.ndarray:
    """Euclidean length of 2D vectors v (..., 2): np.linalg.norm(v, axis=-1) bit for bit (x*x + y*y, then the
    root), far faster (numpy reduces a last axis of 2 slowly) and with one temporary where norm makes two."""
    if v.shape[-1] != 2:
        raise ValueError(f"lengths() takes 2D vectors, not {v.shape[-1]}D")
    x, y = v[..., 0], v[..., 1]
    out = np.asarray(x * x)  # an array even for one vector, so the root can be taken in place
    out += y * y
    return np.sqrt(out, out=out)


def painter_order(depth: np.ndarray, faces: np.ndarray, candidates: np.ndarray, frame: int) -> np.ndarray:
    """Candidate triangle ids sorted back to front by centroid depth at one frame (stable, deterministic)."""
    centroid = depth[frame][faces[candidates]].mean(axis=1)
    return candidates[np.argsort(-centroid, kind="stable")].astype(np.int32)
