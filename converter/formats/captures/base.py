"""What every capture reader shares: the WeightTrack it returns and the CaptureLayout entry it registers.

Pure data: no layout knows another; `converter.formats.captures` lists them and picks one by content.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

DEFAULT_FPS = 60.0  # ARKit face tracking runs at 60 Hz; used when a capture gives no rate
MAX_FRAMES = 1_000_000


@dataclass(frozen=True, eq=False)
class WeightTrack:
    """Named blendshape weights over time, with optional head and eye rotations (yaw, pitch, roll) in radians."""

    names: list[str]
    times: np.ndarray  # float64 (T,) seconds from the first frame, as the take recorded them
    values: np.ndarray  # float32 (T, K), weights 0..1
    fps: float  # the take's rate (from its header or the rows' spacing)
    start_timecode: str = ""  # the first frame's timecode as written, or ""
    head: np.ndarray | None = None  # float32 (T, 3) yaw, pitch, roll in radians
    eye_left: np.ndarray | None = None  # float32 (T, 3) yaw, pitch, roll in radians
    eye_right: np.ndarray | None = None
    source: str = ""  # the CaptureLayout.name of the layout the file had

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.values.shape[0])

    @property
    def duration(self) -> float:
        """Seconds the take lasts: its last time plus one frame."""
        return float(self.times[-1] - self.times[0]) + 1.0 / self.fps if self.n_frames else 0.0

    def is_regular(self, tol: float = 0.05) -> bool:
        """Whether frame k is at k / fps (within tol of a frame): the track can be played one row a frame."""
        grid = np.arange(self.n_frames) / self.fps
        return bool(np.all(np.abs(self.times - self.times[0] - grid) <= tol / self.fps))

    def sampled(self, fps: float) -> WeightTrack:
        """The track resampled (linear) onto a regular grid k / fps covering its time span."""
        span = float(self.times[-1] - self.times[0]) if self.n_frames > 1 else 0.0
        n = int(math.floor(span * fps + 1e-6)) + 1
        t = self.times[0] + np.arange(n) / fps

        def interp(a: np.ndarray | None) -> np.ndarray | None:
            if a is None:
                return None
            if self.n_frames == 1:
                return np.repeat(a[:1], n, axis=0)
            cols = [np.interp(t, self.times, a[:, j]) for j in range(a.shape[1])]
            return np.stack(cols, axis=1).astype(np.float32) if cols else np.zeros((n, 0), np.float32)

        return WeightTrack(self.names, t - t[0], interp(self.values), float(fps), self.start_timecode,
                           interp(self.head), interp(self.eye_left), interp(self.eye_right), self.source)


@dataclass(frozen=True)
class CaptureLayout:
    """One capture layout a tool writes: how to recognise its bytes and read them into a WeightTrack."""

    name: str  # stable id, also WeightTrack.source: "livelinkface-csv", "facecap-txt", ...
    label: str  # what a user calls it: "Live Link Face CSV"
    extensions: tuple[str, ...]  # the file suffixes the tool writes, with the dot: (".csv",)
    sniff: Callable[[bytes], bool]  # True when the bytes (the first 64 KiB suffice) are this layout
    parse: Callable[[bytes, str], WeightTrack]  # (whole file, file name for messages) -> track; InputError if bad
    doc: str = ""  # one line: where the layout is documented (tool, doc page)
