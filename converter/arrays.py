"""Array helpers for what numpy does slowly at our sizes."""

from __future__ import annotations

import numpy as np


def unique_ints(x: np.ndarray) -> np.ndarray:
    """np.unique of integers x (sorted distinct values, flattened) by one sort. Since numpy 2.3 np.unique finds the
    distinct values with a hash table, which on millions of distinct int64 is 50-300x slower than sorting: the
    drawing-order pairs of the 128k-triangle bench face (11 M codes) took 11.5 s, a sort 0.2 s."""
    s = np.sort(np.asarray(x).ravel())
    if not len(s):
        return s
    keep = np.empty(len(s), bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]
