"""MPEG-4 face animation: FAP streams, FDPs, automatic face definition tables, deformation, levels of articulation.

`drive(face, fap, fdp)` turns a FAP stream plus a face mesh into a FaceAnimation every writer can convert.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.mpeg4 import loa
from converter.mpeg4.deform import deform
from converter.mpeg4.fap import FapStream, read_fap, write_fap
from converter.mpeg4.fdp import Fdp, fapu_from_points, fdp_to_json, load_fdp, save_fdp
from converter.mpeg4.tables import FaceDefTables, build_tables

__all__ = ["FapStream", "read_fap", "write_fap", "Fdp", "load_fdp", "save_fdp", "fapu_from_points",
           "FaceDefTables", "build_tables", "deform", "drive", "tables_for", "resample"]

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
_TABLES_CACHE: dict[str, FaceDefTables] = {}


def tables_for(vertices: np.ndarray, faces: np.ndarray, fdp: Fdp) -> FaceDefTables:
    """build_tables with a small in-process cache keyed by the mesh and FDP contents."""
    h = hashlib.sha1(np.ascontiguousarray(vertices, np.float32).tobytes())
    h.update(np.ascontiguousarray(faces, np.int32).tobytes())
    h.update(fdp_to_json(fdp).encode())
    key = h.hexdigest()
    if key not in _TABLES_CACHE:
        if len(_TABLES_CACHE) > 4:
            _TABLES_CACHE.pop(next(iter(_TABLES_CACHE)))
        _TABLES_CACHE[key] = build_tables(vertices, faces, fdp)
    return _TABLES_CACHE[key]


def resample(values: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Linear resampling of (T, 68) values from one frame rate to another (same duration)."""
    t = len(values)
    n = max(1, int(round(t * fps_out / fps_in)))
    pos = np.minimum(np.arange(n) * (fps_in / fps_out), t - 1)
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, t - 1)
    f = (pos - i0)[:, None]
    return values[i0] * (1 - f) + values[i1] * f


def _find_fdp(face: FaceAnimation) -> Fdp:
    """The face's own FDP: one carried in its extras, a <name>.fdp.json beside its source, or the bundled sample's."""
    extra = face.extras.get("fdp")
    if isinstance(extra, Fdp):
        return extra
    candidates = []
    src = face.extras.get("source_path")
    if src:
        candidates.append(Path(src).with_name(f"{Path(src).stem}.fdp.json"))
    candidates.append(SAMPLES / f"{face.name}.fdp.json")
    for c in candidates:
        if c.is_file():
            fdp = load_fdp(c)
            if fdp.vertex_count in (None, face.n_vertices):
                return fdp
    raise InputError(f"no feature-point definition (FDP) found for {face.name!r}; pass --fdp FILE or make one with "
                     "`facesvg fdp INPUT --auto -o face.fdp.json`.")


def drive(face: FaceAnimation, fap: FapStream | str | Path, fdp: Fdp | str | Path | None = None,
          fps: float | None = None) -> FaceAnimation:
    """The face (its frame 0 is the neutral) animated by a FAP stream, resampled to fps when given."""
    stream = fap if isinstance(fap, FapStream) else read_fap(Path(fap))
    if stream.extra.get("loa", "high") != "high":
        stream = loa.expand(stream)  # a reduced stream carries one value per FAP group
    neutral = face.frames[0]
    if fdp is None:
        fdp = _find_fdp(face)
    elif not isinstance(fdp, Fdp):
        fdp = load_fdp(fdp, neutral)
    fdp.check(face.n_vertices)
    tables = tables_for(neutral, face.faces, fdp)
    values = stream.low_level()
    out_fps = float(fps) if fps else float(stream.fps)
    if out_fps != stream.fps:
        values = resample(values, stream.fps, out_fps)
    frames = deform(neutral, tables, values, tables.fapu)
    used = sorted(int(k) + 1 for k in np.flatnonzero(stream.mask.any(0)) if k >= 2)
    idle = [f for f in used if f in tables.missing]
    extras = {**face.extras, "fap": stream.name, "fap_frames": stream.n_frames,
              "faps_used": len(used), "faps_not_animated": idle}
    return face.with_frames(frames, fps=out_fps, extras=extras)
