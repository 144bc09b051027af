"""Paths' tracks stored once per vertex: the encoder's largest input, a quarter of its dense size.

A path (triangle) is keyed on its three corners' px per frame, a (T, 6) track. Neighbouring triangles share
corners, so a dense (T, P, 6) array holds every vertex about six times over (3 corners, each vertex in ~6
triangles, against P ~ 2V); on a long capture it was the plan's largest array. ``Tracks`` keeps one (T, W, 2)
table of vertex positions and each path's three rows of it, and gives the dense tracks of the paths asked for,
a block at a time. The values are the table's, bit for bit: a vertex worked out once is what each of its
corners held when they were worked out one by one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Tracks(NamedTuple):
    """Tracks of P paths over T frames: path j's corner c at frame k is verts[k, corners[j, c]]."""

    verts: np.ndarray  # float (T, W, 2) px, float32 as the Sheet stores them
    corners: np.ndarray  # int (P, 3) rows of verts

    @classmethod
    def screen(cls, xy: np.ndarray, corners: np.ndarray) -> Tracks:
        """The screen tracks of triangles with vertex ids corners (P, 3) over a Sheet's xy (T, V, 2): float32 as
        the Sheet stores them, no copy when it does."""
        return cls(np.asarray(xy, np.float32), corners)

    @property
    def shape(self) -> tuple[int, int, int]:
        """(T, P, 6), the dense array's shape."""
        return self.verts.shape[0], len(self.corners), 6

    def take(self, paths: np.ndarray | slice) -> np.ndarray:
        """The dense tracks (T, n, 6) of paths (indices or a slice), in the table's dtype."""
        c = self.corners[paths]
        return np.take(self.verts, c, axis=1).reshape(self.verts.shape[0], len(c), 6)

    def reorder(self, order: np.ndarray) -> Tracks:
        """The same tracks with the paths in order (indices into these paths): no vertex copied."""
        return Tracks(self.verts, self.corners[order])


def first_use(ids: np.ndarray, n: int) -> np.ndarray:
    """The distinct values of ids (integers in 0..n-1, read flattened) in the order they first occur."""
    flat = np.asarray(ids, np.int64).ravel()
    first = np.full(n, len(flat), np.int64)
    np.minimum.at(first, flat, np.arange(len(flat)))
    used = np.flatnonzero(first < len(flat))
    return used[np.argsort(first[used], kind="stable")]


def blocks(n: int, size: int) -> list[slice]:
    """Consecutive slices of at most size (>= 1) covering 0..n."""
    size = max(1, size)
    return [slice(a, min(a + size, n)) for a in range(0, n, size)]
