"""FaceAnimation: the one 3D type every loader produces and every 3D stage maps to a new one.

Colour convention: Part.color and vertex_colors are display (sRGB-encoded) values 0..1, as OBJ/MTL Kd, PLY
colours and DEFAULT_PART_COLORS are in practice; a vertex colour multiplies its part's colour as display values.
Loaders of linear-light formats convert at load time (glTF: baseColorFactor and COLOR_0 are linear, base-colour
textures sRGB; formats/gltf/scene.py). Lighting decodes to linear, lights and encodes once (converter/lighting.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from converter.errors import InputError

DEFAULT_PART_COLORS: dict[str, tuple[float, float, float]] = {
    "skin": (0.85, 0.66, 0.55),
    "eye": (0.95, 0.95, 0.93),
    "iris": (0.30, 0.40, 0.55),
    "teeth": (0.95, 0.93, 0.85),
    "mouth": (0.55, 0.20, 0.22),
    "lashes": (0.10, 0.08, 0.07),
}


# No mesh has a coordinate this far out (in any unit): beyond it, the float32 squares of normals and areas overflow
# and turn into NaN downstream, so such a position is refused with the NaN and infinite ones.
MAX_COORDINATE = 1e15
CHECK_FRAMES = 64  # frames checked at a time (a (T, V, 3) temporary of a long capture would be GBs)


class NonFinitePositions(InputError):
    """A FaceAnimation's frames hold NaN, infinite or absurdly large positions (formats.load names the file)."""


def _check_positions(frames: np.ndarray) -> None:
    """NonFinitePositions naming the first vertex and frame whose position is NaN, infinite or beyond
    MAX_COORDINATE."""
    for s in range(0, len(frames), CHECK_FRAMES):
        ok = np.abs(frames[s:s + CHECK_FRAMES]) <= MAX_COORDINATE  # False for NaN
        if ok.all():
            continue
        k, v = (int(i) for i in np.argwhere(~ok.all(axis=2))[0])
        value = frames[s + k, v]
        what = ("a NaN or infinite position" if not np.isfinite(value).all()
                else f"a coordinate beyond ±{MAX_COORDINATE:g} ({float(np.abs(value).max()):g})")
        raise NonFinitePositions(f"vertex {v} of frame {s + k} has {what}; fix or re-export the animation.")


@dataclass(frozen=True)
class Part:
    """A group of triangles: semantic name (skin, eye, iris, teeth, mouth, lashes), display base colour, label.

    name is what stages select by (cloning, MPEG-4, rigid groups); label is the source's own name for the group
    (e.g. "Wolf3D_Head/Wolf3D_Skin", node/material), shown by `facesvg info`; it defaults to name."""

    name: str
    color: tuple[float, float, float]
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            object.__setattr__(self, "label", self.name)


@dataclass(frozen=True, eq=False)
class FaceAnimation:
    """Animated triangle mesh: per-frame vertex positions over one fixed topology."""

    frames: np.ndarray  # float32 (T, V, 3), scene units
    faces: np.ndarray  # int32 (F, 3)
    part_ids: np.ndarray  # int32 (F,), index into parts
    parts: tuple[Part, ...]
    fps: float
    name: str = "face"
    vertex_colors: np.ndarray | None = None  # float32 (V, 3) multiplies the part colour, or None
    uvs: np.ndarray | None = None  # float32 (V, 2)
    texture: bytes | None = None  # encoded image (PNG/JPEG)
    extras: dict = field(default_factory=dict)  # loader facts for `info` (morph targets, animated nodes)

    def __post_init__(self) -> None:
        frames = np.ascontiguousarray(self.frames, dtype=np.float32)
        faces = np.ascontiguousarray(self.faces, dtype=np.int32)
        part_ids = np.ascontiguousarray(self.part_ids, dtype=np.int32)
        if frames.ndim != 3 or frames.shape[2] != 3:
            raise InputError(f"animation frames must be (frames, vertices, 3), got shape {frames.shape}.")
        if frames.shape[0] == 0:
            raise InputError("the animation has zero frames; export at least one frame.")
        if frames.shape[1] == 0:
            raise InputError("the mesh has no vertices; export a mesh with geometry.")
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
            raise InputError("the mesh has no triangles; export a mesh with faces.")
        if faces.min() < 0 or faces.max() >= frames.shape[1]:
            raise InputError("a triangle refers to a vertex that does not exist; the file is corrupt.")
        _check_positions(frames)
        if part_ids.shape != (faces.shape[0],) or (len(self.parts) and part_ids.max() >= len(self.parts)):
            raise InputError("part ids do not match the triangles; the file is corrupt.")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise InputError(f"fps must be a positive number, got {self.fps}.")
        if self.vertex_colors is not None:
            vc = np.ascontiguousarray(self.vertex_colors, dtype=np.float32)
            if vc.shape != (frames.shape[1], 3):
                raise InputError("vertex colours do not match the vertex count; the file is corrupt.")
            object.__setattr__(self, "vertex_colors", vc)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "faces", faces)
        object.__setattr__(self, "part_ids", part_ids)
        for a in (frames, faces, part_ids):
            a.setflags(write=False)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.frames.shape[0])

    @property
    def n_vertices(self) -> int:
        """Number of vertices V."""
        return int(self.frames.shape[1])

    @property
    def n_faces(self) -> int:
        """Number of triangles F."""
        return int(self.faces.shape[0])

    @property
    def duration(self) -> float:
        """Seconds the animation lasts: frame k shows from k/fps to (k+1)/fps."""
        return self.n_frames / self.fps

    def with_frames(self, frames: np.ndarray, **changes) -> FaceAnimation:
        """A copy with other vertex positions (same topology) and any other fields changed."""
        return replace(self, frames=frames, **changes)

    def sliced(self, start: int = 0, end: int | None = None) -> FaceAnimation:
        """Frames start..end-1 (clamped); raises InputError when the range is empty."""
        end = self.n_frames if end is None else end
        if not (0 <= start < end <= self.n_frames):
            raise InputError(
                f"frame range {start}..{end} is empty or outside 0..{self.n_frames}; choose --start/--end inside it."
            )
        return replace(self, frames=self.frames[start:end])

    def face_base_colors(self) -> np.ndarray:
        """Per-vertex base colour (V, 3): part colour, times vertex colour when present."""
        part_rgb = np.array([p.color for p in self.parts], dtype=np.float32).reshape(-1, 3)
        rgb = np.ones((self.n_vertices, 3), np.float32)
        # A vertex shared by several parts takes the colour of the last face that names it.
        rgb[self.faces.reshape(-1)] = np.repeat(part_rgb[self.part_ids], 3, axis=0)
        if self.vertex_colors is not None:
            rgb = rgb * self.vertex_colors
        return rgb

    def triangle_colors(self) -> np.ndarray:
        """Per-triangle base colour (F, 3): part colour times the mean vertex colour."""
        part_rgb = np.array([p.color for p in self.parts], dtype=np.float32).reshape(-1, 3)
        rgb = part_rgb[self.part_ids]
        if self.vertex_colors is not None:
            rgb = rgb * self.vertex_colors[self.faces].mean(axis=1)
        return rgb.astype(np.float32)


def vertex_normals(frames: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals for every frame, (T, V, 3)."""
    fn = face_normals(frames, faces, normalize=False)
    t, v = frames.shape[0], frames.shape[1]
    out = np.zeros((t, v, 3), np.float64)
    for k in range(3):
        # np.add.at is slow; accumulate per coordinate with bincount over a flattened (frame, vertex) index.
        idx = (np.arange(t)[:, None] * v + faces[None, :, k]).reshape(-1)
        for c in range(3):
            out[..., c] += np.bincount(idx, weights=fn[..., c].reshape(-1), minlength=t * v).reshape(t, v)
    n = np.linalg.norm(out, axis=-1, keepdims=True)
    return (out / np.where(n > 0, n, 1)).astype(np.float32)


def face_normals(frames: np.ndarray, faces: np.ndarray, normalize: bool = True) -> np.ndarray:
    """Per-frame triangle normals (T, F, 3); area-weighted when normalize is False."""
    a, b, c = (np.take(frames, faces[:, i], axis=1) for i in range(3))
    n = np.cross(b - a, c - a)
    if normalize:
        ln = np.linalg.norm(n, axis=-1, keepdims=True)
        n = n / np.where(ln > 0, ln, 1)
    return n.astype(np.float32)
