"""Sheet: the chapter's 2D data cache, everything a writer needs and nothing 3D."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from converter.camera import Camera


@dataclass(frozen=True, eq=False)
class Sheet:
    """Per-frame projected vertices, triangle visibility, shading and the drawing order."""

    camera: Camera
    fps: float
    xy: np.ndarray  # float32 (T, V, 2) viewport pixels, y down
    depth: np.ndarray  # float32 (T, V) NDC depth, larger is farther
    faces: np.ndarray  # int32 (F, 3) every triangle of the input
    visible: np.ndarray  # bool (T, F) frustum + back-face culling, per frame
    kept: np.ndarray  # bool (F,) triangles seen in at least one frame (occlusion pass), else visible.any(0)
    order: np.ndarray  # int32 (K,) kept triangle ids, back to front
    face_rgb: np.ndarray  # float32 (T, K, 3) flat Lambert colour of the K kept triangles (by id), display 0..1
    vertex_rgb: np.ndarray | None  # float32 (T, V, 3) lit per-vertex colour for Gouraud, 0..1; None when flat
    part_ids: np.ndarray  # int32 (F,)
    part_names: tuple[str, ...]
    neutral: int = 0
    name: str = "face"
    references: dict[int, np.ndarray] = field(default_factory=dict)  # frame -> (H, W, 3) uint8 prerender
    info: dict = field(default_factory=dict)  # counts and facts for the report and metadata

    def __post_init__(self) -> None:
        if self.face_rgb.shape[1] != int(np.count_nonzero(self.kept)):
            raise ValueError(f"face_rgb has {self.face_rgb.shape[1]} columns for {np.count_nonzero(self.kept)} kept "
                             "triangles")

    def color_columns(self, tris: np.ndarray) -> np.ndarray:
        """face_rgb's columns (int64) of the kept triangles tris (ValueError for one never seen: it has no colour,
        and no writer draws it)."""
        tris = np.asarray(tris, np.int64)
        if not self.kept[tris].all():
            raise ValueError("a triangle that is never seen has no flat colour (Sheet.kept)")
        return (np.cumsum(self.kept, dtype=np.int64) - 1)[tris]

    def face_colors(self, tris: np.ndarray) -> np.ndarray:
        """Flat colours (T, n, 3) float32 of the kept triangles tris."""
        return np.take(self.face_rgb, self.color_columns(tris), axis=1)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.xy.shape[0])

    @property
    def duration(self) -> float:
        """Seconds: frame k shows at t = k / fps."""
        return self.n_frames / self.fps
