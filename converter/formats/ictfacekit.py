"""The ICT FaceKit head (MIT): neutral mesh, parts by material, expression shapes as deltas, landmarks.

An input format: `convert FACE --weights CAPTURE` reads an ICT FaceKit folder as a face with named morph targets
(converter/formats/morphs.py). The sample scripts (samples/make_sample.py, make_fdp.py), bench and tests read it too.
"""

from __future__ import annotations

import gzip
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from converter.animation import DEFAULT_PART_COLORS, Part
from converter.errors import InputError
from converter.formats.obj import parse_obj, parse_obj_vertices

# Material -> our part; the transparent overlay meshes (eye blend, occlusion, lacrimal fluid) are left out.
MATERIAL_PARTS = {
    "M_Face": "skin",
    "M_BackHead": "skin",
    "M_GumsTongue": "mouth",
    "M_Teeth": "teeth",
    "M_ScleraLeft": "eye",
    "M_ScleraRight": "eye",
    "M_IrisLeft": "iris",
    "M_IrisRight": "iris",
    "M_EyeLashes": "lashes",
}
PART_ORDER = ("skin", "mouth", "teeth", "eye", "iris", "lashes")
EYEBALL_LEFT = (21451, 23021)  # vertex id ranges from the FaceKit README
EYEBALL_RIGHT = (23021, 24591)


@dataclass(frozen=True)
class IctHead:
    """Neutral vertices (V,3) in cm, triangles (F,3), part ids, parts, expression deltas, landmark vertex ids."""

    vertices: np.ndarray
    faces: np.ndarray
    part_ids: np.ndarray
    parts: tuple[Part, ...]
    landmarks: np.ndarray  # the 68 facial landmark vertex ids
    folder: Path

    def expression_names(self) -> list[str]:
        """Names of the expression shapes present in the folder."""
        return sorted(p.name[: -len(".obj.gz")] for p in (self.folder / "FaceXModel").glob("*.obj.gz")
                      if not p.name.startswith("generic_neutral"))

    def delta(self, name: str) -> np.ndarray:
        """Expression shape minus neutral, (V, 3) float32."""
        path = self.folder / "FaceXModel" / f"{name}.obj.gz"
        if not path.exists():
            raise InputError(f"ICT expression {name!r} not found in {path.parent}.")
        shape = parse_obj_vertices(gzip.decompress(path.read_bytes()).decode(), path.name)
        if shape.shape != self.vertices.shape:
            raise InputError(f"ICT expression {name} has {len(shape)} vertices, the neutral has {len(self.vertices)}.")
        return shape - self.vertices


def load_ict_head(folder: str | Path) -> IctHead:
    """Read an ICT FaceKit folder (FaceXModel/generic_neutral_mesh.obj.gz, vertex_indices.json)."""
    folder = Path(folder)
    neutral = folder / "FaceXModel" / "generic_neutral_mesh.obj.gz"
    if not neutral.exists():
        raise InputError(f"{folder} is not an ICT FaceKit folder (no FaceXModel/generic_neutral_mesh.obj.gz).")
    v, f, g, groups = parse_obj(gzip.decompress(neutral.read_bytes()).decode(), neutral.name)
    part_of_group = np.array([PART_ORDER.index(MATERIAL_PARTS[n]) if n in MATERIAL_PARTS else -1 for n in groups])
    pid = part_of_group[g]
    keep = pid >= 0
    parts = tuple(Part(n, DEFAULT_PART_COLORS[n]) for n in PART_ORDER)
    landmarks = np.array(json.loads((folder / "vertex_indices.json").read_text())["idx_to_landmark_verts"], np.int32)
    return IctHead(v, f[keep], pid[keep].astype(np.int32), parts, landmarks, folder)
