"""The 2D FAT stage (chapter 12.4.4.1): a face, its FDP and a FAP stream -> the 2D data the fap2d writer packs.

The face is prerendered from the front (portrait and mouth layers); its visible triangles become a 2D mesh over the
portrait; per low-level FAP, the 3D engine's displacements of that FAP alone at a few amplitudes are projected to 2D
and quantised (the 2D FAT, piecewise linear in between). Rendering and projecting go through converter.extract.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import ConvexHull, QhullError

from converter import extract as extraction
from converter.animation import FaceAnimation, Part
from converter.camera import Camera
from converter.errors import InputError
from converter.mpeg4 import FapStream, deform, read_fap, resample, tables_for, write_fap
from converter.mpeg4.fdp import load_fdp
from converter.mpeg4.standard import N_FAPS, fap_table
from converter.options import ConversionOptions, Progress, Report, no_progress

XY_STEP = 1 / 16  # px: quantum of the neutral 2D mesh coordinates
MIN_STEP = 1 / 16  # px: finest quantum of the 2D FAT displacements
# Each FAP's displacements are int8 in units of its own power-of-two step, the smallest with |d| <= 127 steps:
# the error at a breakpoint is at most half a step, i.e. under 0.4 % of that FAP's largest displacement.
# Default table reach in FAPU units: one full FAPU distance (1024) for lengths, 0.05 rad for angles.
DEFAULT_REACH = {"AU": 5000.0}
DEFAULT_REACH_LENGTH = 1024.0
MOUTH_CAVITY_RGB = (70, 22, 26)
MOUTH_PART_NAMES = ("teeth", "mouth", "tongue", "gums")
MOUTH_FDP_PARTS = ("upper_teeth", "lower_teeth", "tongue")

DeformFn = Callable[[np.ndarray], np.ndarray]
"""values (K, 68) in FAPU units -> vertex positions (K, V, 3) of the face under those values."""


@dataclass(frozen=True, eq=False)
class FapTable:
    """One low-level FAP's 2D table: displacements at its nonzero breakpoints, in units of its own step."""

    fap: int
    name: str
    kind: str  # 'vertices' (per-vertex displacements) or 'translate' (one 2D translation of the moving vertices)
    amplitudes: tuple[float, ...]  # nonzero breakpoints in FAPU units (the displacement at 0 is 0)
    step_px: float
    vertices: np.ndarray  # int64 (n,) 2D mesh vertex ids the displacements belong to
    displacements: np.ndarray  # int8 (K, n or 1, 2), px = value * step_px


@dataclass(frozen=True, eq=False)
class Fat2dSheet:
    """Everything the fap2d writer packs: layers, the quantised neutral 2D mesh, the 2D FAT, the FAP stream."""

    name: str
    camera: Camera
    portrait: np.ndarray  # uint8 (H, W, 4): the neutral face prerendered from the front
    mouth: np.ndarray  # uint8 (H, W, 4): teeth and tongue, drawn between the portrait and the mesh
    mouth_source: str  # 'render', 'default' or 'none'
    xy_step: float
    vertices: np.ndarray  # uint16 (N, 2): neutral 2D positions in units of xy_step (also texture coordinates)
    triangles: np.ndarray  # int64 (F, 3): 2D mesh triangles, back to front
    source_triangles: int  # triangles of the mesh before the invisible and mouth-interior ones were left out
    feature_points: dict[str, list[float]]  # visible feature points, px
    fapu: dict[str, float]
    tables: tuple[FapTable, ...]
    dropped: tuple[dict, ...]  # {"fap", "name", "reason"} of every FAP with no table
    stream: FapStream
    stream_text: str  # the stream as .fap text

    @property
    def n_frames(self) -> int:
        """Frames of the stream."""
        return self.stream.n_frames


def fap_kinds() -> dict[int, str]:
    """FAP number -> how the 2D FAT handles it: 'vertices', 'translate' or a reason it is dropped."""
    kinds: dict[int, str] = {}
    for f in fap_table():
        if f.number in (1, 2):
            kinds[f.number] = "high-level FAP (viseme/expression); its low-level FAPs are in the stream"
        elif f.group == 6:
            kinds[f.number] = "tongue animation is not converted to 2D"
        elif f.group == 7:
            kinds[f.number] = "head rotation is dropped with the third dimension"
        elif f.axis.endswith("z") and f.is_translation:
            kinds[f.number] = "z-direction FAP: little effect on the frontal projection"
        elif f.axis.startswith("rot") and f.group == 3:
            kinds[f.number] = "translate"  # eyeball yaw/pitch become 2D translations of the eye
        else:
            kinds[f.number] = "vertices"
    return kinds


def fap_reach(unit: str, stream_max: float) -> float:
    """Largest |amplitude| a table holds: the default for the unit, widened to the stream's own extreme."""
    base = DEFAULT_REACH.get(unit, DEFAULT_REACH_LENGTH)
    return float(max(base, np.ceil(stream_max)))


def quantum(max_abs: float) -> float:
    """The power-of-two step (>= MIN_STEP) that stores displacements up to max_abs px in int8."""
    return float(max(MIN_STEP, 2.0 ** np.ceil(np.log2(max(max_abs, 1e-12) / 127))))


def amplitudes(reach: float, bidirectional: bool) -> np.ndarray:
    """Breakpoints of the piecewise-linear table, including 0."""
    half = [reach / 2, reach]
    pts = ([-reach, -reach / 2] if bidirectional else []) + [0.0] + half
    return np.array(pts, np.float64)


def mouth_faces(anim: FaceAnimation, fdp) -> np.ndarray:
    """Bool (F,): the mouth-interior triangles (teeth, tongue, gums by part name or by the FDP's parts)."""
    part_of = np.array([p.name.lower() for p in anim.parts])[anim.part_ids] if anim.parts else np.array([])
    sel = np.isin(part_of, MOUTH_PART_NAMES) if part_of.size else np.zeros(anim.n_faces, bool)
    ids = [i for name in MOUTH_FDP_PARTS for i in (getattr(fdp, "parts", {}) or {}).get(name, [])]
    if ids:
        in_part = np.zeros(anim.n_vertices, bool)
        in_part[np.asarray(ids, np.int64)] = True
        sel |= in_part[anim.faces].all(axis=1)
    return sel


def interior_vertices(anim: FaceAnimation, fdp) -> np.ndarray:
    """Bool (V,): vertices only mouth-interior triangles use."""
    inner = mouth_faces(anim, fdp)
    out = np.zeros(anim.n_vertices, bool)
    out[anim.faces[inner].reshape(-1)] = True
    out[anim.faces[~inner].reshape(-1)] = False
    return out


def mouth_layer(
    anim: FaceAnimation, neutral: np.ndarray, camera: Camera, fdp, points_xy: dict[str, np.ndarray]
) -> tuple[np.ndarray, str]:
    """RGBA (H, W, 4) teeth-and-tongue layer and how it was made ('render', 'default' or 'none')."""
    h, w = camera.height, camera.width
    sel = mouth_faces(anim, fdp)
    if sel.any():
        faces = anim.faces[sel]
        sub = FaceAnimation(neutral[None], faces, anim.part_ids[sel], anim.parts, anim.fps, "mouth", anim.vertex_colors)
        sheet = extraction.extract(sub, camera, occlusion=False, reference_frames=(0,))
        img = Image.new("RGBA", (w, h), (0, 0, 0, 0))
        used = np.unique(faces)
        xy = sheet.xy[0][used].astype(np.float64)
        try:
            hull = xy[ConvexHull(xy).vertices]
            ImageDraw.Draw(img).polygon([tuple(p) for p in hull], fill=MOUTH_CAVITY_RGB + (255,))
        except (QhullError, ValueError):
            pass
        img.alpha_composite(Image.fromarray(sheet.references[0], "RGBA"))
        return np.asarray(img), "render"
    lips = [points_xy[k] for k in ("8.3", "8.4", "2.2", "2.3", "8.1", "8.2", "2.4", "2.5") if k in points_xy]
    if len(lips) < 2:
        return np.zeros((h, w, 4), np.uint8), "none"
    p = np.array(lips)
    cx, cy = p.mean(axis=0)
    half_w = max(float(np.ptp(p[:, 0])) / 2, 2.0)
    half_h = max(float(np.ptp(p[:, 1])) / 2, half_w * 0.45)
    img = Image.new("RGBA", (w, h), (0, 0, 0, 0))
    d = ImageDraw.Draw(img)
    d.ellipse([cx - half_w, cy - half_h, cx + half_w, cy + half_h], fill=MOUTH_CAVITY_RGB + (255,))
    d.rectangle([cx - half_w * 0.7, cy - half_h, cx + half_w * 0.7, cy - half_h * 0.45], fill=(238, 234, 222, 255))
    d.ellipse([cx - half_w * 0.55, cy + half_h * 0.1, cx + half_w * 0.55, cy + half_h * 0.9], fill=(150, 55, 60, 255))
    return np.asarray(img), "default"


def build(
    anim: FaceAnimation,
    fdp,
    stream: FapStream,
    deform_fn: DeformFn,
    options: ConversionOptions | None = None,
    mesh_faces: np.ndarray | None = None,
    progress: Progress = no_progress,
) -> Fat2dSheet:
    """The 2D FAT data of a face (neutral = options.neutral_frame) driven by deform_fn and a FAP stream.

    mesh_faces: the 2D mesh's triangles when they differ from the face's (e.g. a simplified mesh); the portrait
    is always rendered from the full face."""
    options = options or ConversionOptions(to="fap2d")
    if not 0 <= options.neutral_frame < anim.n_frames:
        raise InputError(f"neutral frame {options.neutral_frame} is outside 0..{anim.n_frames - 1}; choose one inside.")
    neutral = np.asarray(anim.frames[options.neutral_frame], np.float64)
    values = np.asarray(stream.low_level(), np.float64)
    if values.shape[0] == 0:
        raise InputError("the FAP stream has no frames; give a stream with at least one frame.")
    kinds = fap_kinds()
    # Frame the neutral face and the whole driven 3D animation from the front.
    driven = np.asarray(deform_fn(values), np.float32)
    camera = Camera.fit(np.concatenate([neutral[None].astype(np.float32), driven]), size=options.size, yaw=0.0,
                        pitch=0.0, fov=options.fov, ortho=options.ortho)
    progress("portrait", 0.2)
    base = FaceAnimation(neutral[None], anim.faces, anim.part_ids, anim.parts, anim.fps, anim.name,
                         anim.vertex_colors)
    sheet = extraction.extract(base, camera, occlusion=True, reference_frames=(0,))
    portrait = sheet.references[0]
    if mesh_faces is not None:
        mesh = FaceAnimation(neutral[None], mesh_faces, np.zeros(len(mesh_faces), np.int32), (Part("skin", (1, 1, 1)),),
                             anim.fps, anim.name)
        msheet = extraction.extract(mesh, camera, occlusion=True)
        faces, order = mesh.faces, msheet.order
    else:
        faces, order = anim.faces, sheet.order
    # Teeth, tongue and gums seen through the lips belong to the mouth layer, not to the warped face: as mesh
    # triangles they would be stretched between the parting lips.
    order = order[~interior_vertices(anim, fdp)[faces[order]].all(axis=1)]
    if order.size == 0:
        raise InputError("no triangle of the face is visible from the front; check the mesh orientation (+z forward).")
    used, tri = np.unique(faces[order], return_inverse=True)
    tri = tri.reshape(-1, 3)
    xy0 = camera.project(neutral[used])[0]
    q_xy = np.round(xy0 / XY_STEP)
    if q_xy.min() < 0 or q_xy.max() > 65535:
        raise InputError("the face projects outside the portrait; lower --size.")
    xy0 = q_xy * XY_STEP  # both players start from the quantised positions
    progress("tables", 0.4)

    # 2D feature points: those whose vertex lies on a triangle visible from the front.
    slot = np.full(anim.n_vertices, -1, np.int64)
    slot[used] = np.arange(len(used))
    points = {}
    for name in sorted(fdp.points, key=_point_key):
        s = slot[fdp.points[name]]
        if s >= 0:
            points[name] = [round(float(xy0[s, 0]), 2), round(float(xy0[s, 1]), 2)]

    stream_max = np.abs(values).max(axis=0)
    tables, dropped = [], []
    for f in fap_table():
        kind = kinds[f.number]
        if kind not in ("vertices", "translate"):
            dropped.append({"fap": f.number, "name": f.name, "reason": kind})
            continue
        amps = amplitudes(fap_reach(f.unit, stream_max[f.number - 1]), f.bidirectional)
        vals = np.zeros((len(amps), N_FAPS))
        vals[:, f.number - 1] = amps
        moved3 = np.asarray(deform_fn(vals), np.float64)[:, used]  # (K, n, 3)
        nonzero = amps != 0
        disp = (camera.project(moved3)[0] - xy0)[nonzero]  # (K-1, n, 2); zero displacement at amplitude 0
        if kind == "translate":
            moving = np.abs(moved3 - neutral[used]).max(axis=(0, 2)) > 1e-6 * max(float(np.ptp(neutral)), 1e-9)
            sel = np.flatnonzero(moving)
            disp = disp[:, sel].mean(axis=1, keepdims=True) if sel.size else disp[:, :0]
        step = quantum(float(np.abs(disp).max(initial=0.0)))
        if kind == "vertices":
            sel = np.flatnonzero(np.abs(disp).max(axis=(0, 2)) >= step / 2)
            disp = disp[:, sel]
        qd = np.round(disp / step)
        if sel.size == 0 or not qd.any():
            dropped.append({"fap": f.number, "name": f.name, "reason": "no visible 2D displacement on this face"})
            continue
        tables.append(FapTable(f.number, f.name, kind, tuple(float(a) for a in amps[nonzero]), step,
                               sel.astype(np.int64), qd.astype(np.int8)))
    progress("layers", 0.8)
    mouth, mouth_source = mouth_layer(anim, neutral, camera, fdp, {k: np.array(v) for k, v in points.items()})
    return Fat2dSheet(
        name=anim.name, camera=camera, portrait=portrait, mouth=mouth, mouth_source=mouth_source, xy_step=XY_STEP,
        vertices=q_xy.astype(np.uint16), triangles=tri, source_triangles=int(len(faces)), feature_points=points,
        fapu={k: float(v) for k, v in sorted((getattr(fdp, "fapu", {}) or {}).items())},
        tables=tuple(tables), dropped=tuple(dropped), stream=stream, stream_text=write_fap(stream),
    )


def _point_key(name: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in name.split("."))
    except ValueError:
        return (1 << 30,)


def engine_deform(anim: FaceAnimation, fdp, neutral: np.ndarray) -> DeformFn:
    """The MPEG-4 engine's deformation of this face (tables built once), as a DeformFn."""
    tables = tables_for(neutral, anim.faces, fdp)
    return lambda values: deform(neutral, tables, values, tables.fapu)


def resampled(stream: FapStream, fps: float) -> FapStream:
    """The stream at another frame rate (linear in the values, nearest frame's mask; FAP 1-2 extras dropped)."""
    values = resample(stream.values, stream.fps, fps)
    idx = np.minimum(np.round(np.arange(len(values)) * stream.fps / fps).astype(np.int64), stream.n_frames - 1)
    extra = {k: v for k, v in stream.extra.items() if k not in ("fap1", "fap2")}
    return FapStream(stream.name, float(fps), values, stream.mask[idx], extra)


def stage(anim: FaceAnimation, options: ConversionOptions, report: Report,
          progress: Progress = no_progress) -> Fat2dSheet:
    """The 2D FAT data of the (undriven) face with options.fap and options.fdp: the fap2d output's stage."""
    if not options.fap:
        raise InputError("--to fap2d needs a FAP stream; give one with --fap FILE.fap.")
    if not options.fdp:
        raise InputError("--to fap2d needs the face's feature points; give them with --fdp FILE (JSON or Xface .fdp).")
    t0 = time.perf_counter()
    fap_path = Path(options.fap)
    if not fap_path.is_file():
        raise InputError(f"FAP stream {fap_path} does not exist; check the --fap path.")
    stream = read_fap(fap_path)
    if options.fps and options.fps != stream.fps:
        stream = resampled(stream, options.fps)
    if not 0 <= options.neutral_frame < anim.n_frames:
        raise InputError(f"neutral frame {options.neutral_frame} is outside 0..{anim.n_frames - 1}; choose one inside.")
    neutral = np.asarray(anim.frames[options.neutral_frame], np.float64)
    fdp = load_fdp(options.fdp, vertices=neutral)
    deform_fn = engine_deform(anim, fdp, neutral)
    report.timings["tables"] = time.perf_counter() - t0
    progress("fap2d", 0.1)
    t = time.perf_counter()
    sheet = build(anim, fdp, stream, deform_fn, options, progress=progress)
    report.timings["fat2d"] = time.perf_counter() - t
    report.counts.update({
        "frames": sheet.n_frames,
        "triangles": sheet.source_triangles,
        "triangles_kept": int(len(sheet.triangles)),
        "vertices_2d": int(len(sheet.vertices)),
        "feature_points_2d": len(sheet.feature_points),
        "faps_converted": len(sheet.tables),
        "faps_dropped": len(sheet.dropped),
    })
    if sheet.mouth_source == "none":
        report.warnings.append("no teeth, tongue or lip feature points found: the mouth layer is empty.")
    return sheet
