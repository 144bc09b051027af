"""The position tolerance split once into what the bounded encoding spends it on.

A drawn vertex may be off by ``tolerance`` px at any frame. The encoding spends that on four things, in this
order: rounding the coordinates to an integer grid (``scale`` units per px, QUANT_SHARE of the tolerance at
most), rounding keyTimes (TIME_SHARE), the players' float arithmetic on numbers this large (``float_err``), and
what is left, ``keys``, on keyframing (linear interpolation within that many px of the exact position). Paths
inside a group transform keyframe local coordinates that the group's linear part magnifies: ``local_keys``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

QUANT_SHARE = 0.25  # share of the tolerance spent on integer rounding (the rest on keyframes)
TIME_SHARE = 0.015  # share of the tolerance spent on rounding keyTimes
# Relative float error per px of extent: a player's float32 arithmetic (2e-7) plus three float32 roundings (2^-24
# each) of what the encoder stores as float32 to bound its memory: the tracks (groups.Layout.head_local), the key
# values (freeknots.point_keys) and the values interpolated at a hidden run's edges (collapse.fold).
FLOAT_ERR_PER_PX = 2e-7 + 3 * 2.0 ** -24


def viewbox_scale(tolerance: float) -> int:
    """Viewport px -> integer units: rounding (at most step/sqrt 2 px) takes QUANT_SHARE of the bound."""
    return max(1, math.ceil(1.0 / (math.sqrt(2) * QUANT_SHARE * tolerance)))


class ErrorBudget(NamedTuple):
    """A tolerance (px) and its parts: grid rounding, keyTime rounding, float error, keyframing (module docstring)."""

    tolerance: float  # px the output may differ from the exact projection at any drawn vertex and frame
    scale: int  # integer units per px of the coordinate grid
    rounding: float  # px: worst rounding of a 2D point to that grid, sqrt(1/2) / scale
    keytimes: float  # px: what rounding keyTimes may move a point
    float_err: float  # px: float arithmetic of a player, and the encoder's float32 tracks, on coordinates this large
    keys: float  # px (Euclidean per point) left for keyframing

    @classmethod
    def split(cls, tolerance: float, extent_px: float) -> ErrorBudget:
        """The budget for a tolerance on a viewport whose larger side is extent_px."""
        scale = viewbox_scale(tolerance)
        rounding = math.sqrt(0.5) / scale
        keytimes = TIME_SHARE * tolerance
        float_err = 1e-4 + FLOAT_ERR_PER_PX * extent_px
        return cls(tolerance, scale, rounding, keytimes, float_err, tolerance - rounding - keytimes - float_err)

    @property
    def fit_bound(self) -> float:
        """px a fit whose rounding is checked exactly may use (everything but the float error)."""
        return self.tolerance - self.float_err

    def local_keys(self, gain: np.ndarray) -> np.ndarray:
        """Per path the Euclidean px its local keyframing may use under a transform of error gain (>= sigma_max
        of its linear part): gain * (keys + rounding) + keytimes + float_err <= tolerance."""
        g = np.maximum(np.asarray(gain, np.float64), 1e-9)
        return (self.tolerance - self.keytimes - self.float_err) / g - self.rounding
