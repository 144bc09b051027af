"""A weight capture as the puppet stores it (model.Take): uint8 weights per name per frame, small-integer angles."""

from __future__ import annotations

import numpy as np

from converter.errors import InputError
from converter.formats.captures.base import WeightTrack
from converter.puppet.model import EYE_UNIT, HEAD_UNIT, Take

MAX_FRAMES = 1 << 22  # a take longer than this (19 h at 60 fps) is refused
MAX_NAMES = 255


def _moving(a: np.ndarray | None) -> bool:
    """Whether an angle track is present and not all zero."""
    return a is not None and bool(np.abs(a).max() > 0)


def from_track(track: WeightTrack) -> Take:
    """The Take of a capture: weights clamped to 0..1 in 255 steps, head angles in 0.01 degree, eye angles in 0.5
    degree (their rolls dropped: the puppet turns eyes by yaw and pitch), frame times kept where they are off the
    k / fps grid by more than half a frame."""
    if track.n_frames == 0:
        raise InputError("the capture has no frames; record a take with at least one frame.")
    if track.n_frames > MAX_FRAMES:
        raise InputError(f"the capture has {track.n_frames} frames, more than the puppet stores ({MAX_FRAMES}).")
    if len(track.names) > MAX_NAMES:
        raise InputError(f"the capture has {len(track.names)} weights, more than the puppet stores ({MAX_NAMES}).")
    values = np.nan_to_num(np.asarray(track.values, np.float64), nan=0.0)
    weights = np.rint(np.clip(values, 0.0, 1.0) * 255).astype(np.uint8)
    head = None
    if _moving(track.head):
        head = np.clip(np.rint(np.nan_to_num(track.head, nan=0.0) / HEAD_UNIT), -32767, 32767).astype(np.int16)
    eyes = None
    if _moving(track.eye_left) or _moving(track.eye_right):
        cols = []
        for a in (track.eye_left, track.eye_right):
            a = np.zeros((track.n_frames, 3), np.float32) if a is None else np.nan_to_num(a, nan=0.0)
            cols.append(a[:, :2])
        eyes = np.clip(np.rint(np.concatenate(cols, axis=1) / EYE_UNIT), -127, 127).astype(np.int8)
    times = None
    if not track.is_regular(tol=0.5):
        ms = np.rint((np.asarray(track.times, np.float64) - track.times[0]) * 1000.0)  # rounded once: no drift
        times = np.clip(np.diff(ms, prepend=0.0), 0, 65535).astype(np.uint16)
    return Take(list(track.names), weights, float(track.fps), head, eyes, times, track.source)


def frame_times(take: Take) -> np.ndarray:
    """(T,) seconds of each frame, as the player plays them."""
    if take.times is None:
        return np.arange(take.n_frames) / take.fps
    return np.cumsum(take.times.astype(np.float64)) / 1000.0


def frame_pose(take: Take, k: int) -> tuple[np.ndarray, tuple[float, float, float], tuple[float, float, float, float]]:
    """Frame k's weights (K,) 0..1, head (yaw, pitch, roll) and eyes (left yaw, pitch, right yaw, pitch), radians."""
    w = take.weights[k].astype(np.float64) / 255
    head = (0.0, 0.0, 0.0) if take.head is None else tuple(float(v) * HEAD_UNIT for v in take.head[k])
    eyes = (0.0,) * 4 if take.eyes is None else tuple(float(v) * EYE_UNIT for v in take.eyes[k])
    return w, head, eyes  # type: ignore[return-value]
