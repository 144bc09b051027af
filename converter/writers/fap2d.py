"""The 2D MPEG-4 face package (chapter 12.4.4.1): warped 2D mesh over a prerendered portrait, 2D FAT, FAP stream.

A package is a zip holding manifest.json (format "facesvg-fap2d", schema fap2d.schema.json beside this file),
portrait.png (the neutral face prerendered from the front), mouth.png (teeth and tongue layer, drawn between the
portrait and the mesh), data.bin (little-endian arrays the manifest points into) and stream.fap (the FAP stream).
The 2D FAT holds, per low-level FAP, 2D vertex displacements at a few amplitudes (piecewise linear in between),
made by projecting the 3D engine's displacements of one FAP at a time.
"""

from __future__ import annotations

import io
import json
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import ConvexHull, QhullError

from converter import extract as extraction
from converter.animation import FaceAnimation, Part
from converter.camera import Camera
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, Report, no_progress

FORMAT = "facesvg-fap2d"
VERSION = "1.0"
SCHEMA_PATH = Path(__file__).with_name("fap2d.schema.json")
N_FAPS = 68
XY_STEP = 1 / 16  # px: quantum of the neutral 2D mesh coordinates
MIN_STEP = 1 / 16  # px: finest quantum of the 2D FAT displacements
# Each FAP's displacements are int8 in units of its own power-of-two step, the smallest with |d| <= 127 steps:
# the error at a breakpoint is at most half a step, i.e. under 0.4 % of that FAP's largest displacement.
OVERDRAW_PX = 0.5  # players push each triangle edge out by this much so anti-aliased seams do not show
DIRTY_CELL_PX = 16  # players skip triangles that neither move nor touch a cell where something moved
# Default table reach in FAPU units: one full FAPU distance (1024) for lengths, 0.05 rad for angles.
DEFAULT_REACH = {"AU": 5000.0}
DEFAULT_REACH_LENGTH = 1024.0
MOUTH_CAVITY_RGB = (70, 22, 26)
MOUTH_PART_NAMES = ("teeth", "mouth", "tongue", "gums")
MOUTH_FDP_PARTS = ("upper_teeth", "lower_teeth", "tongue")
ZIP_DATE = (1980, 1, 1, 0, 0, 0)

DeformFn = Callable[[np.ndarray], np.ndarray]
"""values (K, 68) in FAPU units -> vertex positions (K, V, 3) of the face under those values."""


@dataclass
class Package:
    """A built package: the manifest and the other files by name (bytes)."""

    manifest: dict
    files: dict[str, bytes] = field(default_factory=dict)


def fap_kinds() -> dict[int, str]:
    """FAP number -> how the 2D FAT handles it: 'vertices', 'translate' or a reason it is dropped."""
    from converter.mpeg4.standard import fap_table

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


class _Blob:
    """Appends little-endian arrays to one buffer (4-byte aligned) and returns manifest references."""

    def __init__(self) -> None:
        self.buf = bytearray()

    def add(self, array: np.ndarray, dtype: str) -> dict:
        a = np.ascontiguousarray(array, dtype=np.dtype("<" + dtype))
        self.buf.extend(b"\0" * (-len(self.buf) % 4))
        ref = {"offset": len(self.buf), "dtype": dtype, "shape": [int(s) for s in a.shape]}
        self.buf.extend(a.tobytes())
        return ref


def _png(rgba: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgba, np.uint8), "RGBA").save(out, format="PNG", optimize=True)
    return out.getvalue()


def opaque_box(rgba: np.ndarray) -> list[int] | None:
    """[x0, y0, x1, y1] (end exclusive) around the non-transparent pixels, or None when there are none."""
    ys, xs = np.nonzero(rgba[..., 3])
    if not len(xs):
        return None
    return [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1]


def _front_camera(frames: np.ndarray, options: ConversionOptions) -> Camera:
    return Camera.fit(frames, size=options.size, yaw=0.0, pitch=0.0, fov=options.fov, ortho=options.ortho)


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


def build_package(
    anim: FaceAnimation,
    fdp,
    stream,
    stream_text: str,
    deform: DeformFn,
    options: ConversionOptions = ConversionOptions(to="fap2d"),
    mesh_faces: np.ndarray | None = None,
    progress: Progress = no_progress,
) -> Package:
    """Build the package of a face (neutral = options.neutral_frame) driven by deform and a FAP stream."""
    from converter.mpeg4.standard import fap_table

    if not 0 <= options.neutral_frame < anim.n_frames:
        raise InputError(f"neutral frame {options.neutral_frame} is outside 0..{anim.n_frames - 1}; choose one inside.")
    neutral = np.asarray(anim.frames[options.neutral_frame], np.float64)
    values = np.asarray(stream.low_level(), np.float64)
    if values.shape[0] == 0:
        raise InputError("the FAP stream has no frames; give a stream with at least one frame.")
    table = fap_table()
    kinds = fap_kinds()
    # Frame the neutral face and the whole driven 3D animation from the front.
    driven = np.asarray(deform(values), np.float32)
    camera = _front_camera(np.concatenate([neutral[None].astype(np.float32), driven]), options)
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

    blob = _Blob()
    tri_dtype = "u2" if len(used) <= 65536 else "u4"
    mesh_ref = {
        "vertices": blob.add(q_xy.astype(np.uint16), "u2"),
        "xy_step": XY_STEP,
        "triangles": blob.add(tri, tri_dtype),
        "overdraw_px": OVERDRAW_PX,
        "dirty_cell_px": DIRTY_CELL_PX,
    }
    stream_max = np.abs(values).max(axis=0)
    entries, dropped = [], []
    for f in table:
        kind = kinds[f.number]
        if kind not in ("vertices", "translate"):
            dropped.append({"fap": f.number, "name": f.name, "reason": kind})
            continue
        amps = amplitudes(fap_reach(f.unit, stream_max[f.number - 1]), f.bidirectional)
        vals = np.zeros((len(amps), N_FAPS))
        vals[:, f.number - 1] = amps
        moved3 = np.asarray(deform(vals), np.float64)[:, used]  # (K, n, 3)
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
        entries.append({
            "fap": f.number,
            "name": f.name,
            "kind": kind,
            "amplitudes": [float(a) for a in amps[nonzero]],
            "step_px": step,
            "vertices": blob.add(sel.astype(np.uint16 if tri_dtype == "u2" else np.uint32), tri_dtype),
            "displacements": blob.add(qd.astype(np.int8), "i1"),
        })
    progress("layers", 0.8)
    mouth, mouth_source = mouth_layer(anim, neutral, camera, fdp, {k: np.array(v) for k, v in points.items()})
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "name": anim.name,
        "size": [camera.width, camera.height],
        "camera": camera.to_json(),
        "layers": [
            {"name": "portrait", "image": "portrait.png"},
            {"name": "mouth", "image": "mouth.png", "source": mouth_source, "box": opaque_box(mouth)},
            {"name": "face", "mesh": "mesh", "texture": "portrait.png"},
        ],
        "data": "data.bin",
        "mesh": mesh_ref,
        "feature_points": points,
        "fapu": {k: float(v) for k, v in sorted((getattr(fdp, "fapu", {}) or {}).items())},
        "fat2d": {"faps": entries},
        "dropped": dropped,
        "stream": {"file": "stream.fap", "name": stream.name, "fps": float(stream.fps), "frames": int(values.shape[0])},
        "counts": {
            "source_triangles": int(len(faces)),
            "triangles": int(len(tri)),
            "vertices": int(len(used)),
            "feature_points": len(points),
            "faps_converted": len(entries),
            "faps_dropped": len(dropped),
        },
    }
    files = {
        "manifest.json": json.dumps(manifest, separators=(",", ":")).encode(),
        "portrait.png": _png(portrait),
        "mouth.png": _png(mouth),
        "data.bin": bytes(blob.buf),
        "stream.fap": stream_text.encode(),
    }
    return Package(manifest, files)


def _point_key(name: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in name.split("."))
    except ValueError:
        return (1 << 30,)


STORED = ("portrait.png", "mouth.png")  # already compressed


def package_zip(pkg: Package) -> bytes:
    """The package as zip bytes: fixed order and timestamps (deterministic); PNGs stored, the rest deflated."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for name in ("manifest.json", "portrait.png", "mouth.png", "data.bin", "stream.fap"):
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
            info.compress_type = zipfile.ZIP_STORED if name in STORED else zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, pkg.files[name], compresslevel=9)
    return out.getvalue()


def animation_sizes(pkg: Package) -> dict[str, float]:
    """Bytes of FAP stream per second of animation, as text and deflated (what Table 12.4 compares)."""
    import zlib

    raw = pkg.files["stream.fap"]
    seconds = pkg.manifest["stream"]["frames"] / pkg.manifest["stream"]["fps"]
    return {
        "stream_bytes": float(len(raw)),
        "stream_bytes_per_s": len(raw) / seconds,
        "stream_deflated_bytes_per_s": len(zlib.compress(raw, 9)) / seconds,
    }


def engine_deform(anim: FaceAnimation, fdp, neutral: np.ndarray) -> DeformFn:
    """The MPEG-4 engine's deformation of this face (tables built once), as a DeformFn."""
    from converter.mpeg4 import deform, tables_for

    tables = tables_for(neutral, anim.faces, fdp)
    return lambda values: deform(neutral, tables, values, tables.fapu)


def resampled(stream, fps: float):
    """The stream at another frame rate (linear in the values, nearest frame's mask; FAP 1-2 extras dropped)."""
    from converter.mpeg4 import FapStream, resample

    values = resample(stream.values, stream.fps, fps)
    idx = np.minimum(np.round(np.arange(len(values)) * stream.fps / fps).astype(np.int64), stream.n_frames - 1)
    extra = {k: v for k, v in stream.extra.items() if k not in ("fap1", "fap2")}
    return FapStream(stream.name, float(fps), values, stream.mask[idx], extra)


def convert(anim: FaceAnimation, options: ConversionOptions, report: Report, progress: Progress = no_progress):
    """Write the 2D MPEG-4 package of the (undriven) face with options.fap and options.fdp; a Result (zip)."""
    from converter.convert import Result

    if not options.fap:
        raise InputError("--to fap2d needs a FAP stream; give one with --fap FILE.fap.")
    if not options.fdp:
        raise InputError("--to fap2d needs the face's feature points; give them with --fdp FILE (JSON or Xface .fdp).")
    from converter.mpeg4.fap import read_fap, write_fap
    from converter.mpeg4.fdp import load_fdp

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
    deform = engine_deform(anim, fdp, neutral)
    report.timings["tables"] = time.perf_counter() - t0
    progress("fap2d", 0.1)
    t = time.perf_counter()
    pkg = build_package(anim, fdp, stream, write_fap(stream), deform, options, progress=progress)
    data = package_zip(pkg)
    report.timings["fap2d"] = time.perf_counter() - t
    c = pkg.manifest["counts"]
    report.counts.update({
        "frames": pkg.manifest["stream"]["frames"],
        "triangles": c["source_triangles"],
        "triangles_kept": c["triangles"],
        "vertices_2d": c["vertices"],
        "feature_points_2d": c["feature_points"],
        "faps_converted": c["faps_converted"],
        "faps_dropped": c["faps_dropped"],
    })
    report.sizes.update({name: len(b) for name, b in pkg.files.items()})
    report.sizes["output"] = len(data)
    report.figures.update({k: round(v, 1) for k, v in animation_sizes(pkg).items()})
    if pkg.manifest["layers"][1]["source"] == "none":
        report.warnings.append("no teeth, tongue or lip feature points found: the mouth layer is empty.")
    progress("done", 1.0)
    return Result(data, "application/zip", ".zip", report)
