"""The 2D MPEG-4 face package (chapter 12.4.4.1): a zip of the 2D FAT data the mpeg4.fat2d stage built.

A package is a zip holding manifest.json (format "facesvg-fap2d", schema fap2d.schema.json beside this file),
portrait.png (the neutral face prerendered from the front), mouth.png (teeth and tongue layer, drawn between the
portrait and the mesh), data.bin (little-endian arrays the manifest points into) and stream.fap (the FAP stream).
The 2D FAT holds, per low-level FAP, 2D vertex displacements at a few amplitudes (piecewise linear in between).
This module only packs: it reads no files and drives nothing.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from converter.mpeg4.fat2d import Fat2dSheet
from converter.options import ConversionOptions, Progress, Report, no_progress

FORMAT = "facesvg-fap2d"
VERSION = "1.0"
SCHEMA_PATH = Path(__file__).with_name("fap2d.schema.json")
OVERDRAW_PX = 0.5  # players push each triangle edge out by this much so anti-aliased seams do not show
DIRTY_CELL_PX = 16  # players skip triangles that neither move nor touch a cell where something moved
ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@dataclass
class Package:
    """A built package: the manifest and the other files by name (bytes)."""

    manifest: dict
    files: dict[str, bytes] = field(default_factory=dict)


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


def package(sheet: Fat2dSheet) -> Package:
    """The manifest and files of the package of a Fat2dSheet."""
    camera = sheet.camera
    blob = _Blob()
    n_vertices = len(sheet.vertices)
    index_dtype = "u2" if n_vertices <= 65536 else "u4"
    mesh_ref = {
        "vertices": blob.add(sheet.vertices, "u2"),
        "xy_step": sheet.xy_step,
        "triangles": blob.add(sheet.triangles, index_dtype),
        "overdraw_px": OVERDRAW_PX,
        "dirty_cell_px": DIRTY_CELL_PX,
    }
    entries = [{
        "fap": t.fap,
        "name": t.name,
        "kind": t.kind,
        "amplitudes": list(t.amplitudes),
        "step_px": t.step_px,
        "vertices": blob.add(t.vertices, index_dtype),
        "displacements": blob.add(t.displacements, "i1"),
    } for t in sheet.tables]
    dropped = [dict(d) for d in sheet.dropped]
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "name": sheet.name,
        "size": [camera.width, camera.height],
        "camera": camera.to_json(),
        "layers": [
            {"name": "portrait", "image": "portrait.png"},
            {"name": "mouth", "image": "mouth.png", "source": sheet.mouth_source, "box": opaque_box(sheet.mouth)},
            {"name": "face", "mesh": "mesh", "texture": "portrait.png"},
        ],
        "data": "data.bin",
        "mesh": mesh_ref,
        "feature_points": sheet.feature_points,
        "fapu": dict(sheet.fapu),
        "fat2d": {"faps": entries},
        "dropped": dropped,
        "stream": {"file": "stream.fap", "name": sheet.stream.name, "fps": float(sheet.stream.fps),
                   "frames": sheet.n_frames},
        "counts": {
            "source_triangles": sheet.source_triangles,
            "triangles": int(len(sheet.triangles)),
            "vertices": n_vertices,
            "feature_points": len(sheet.feature_points),
            "faps_converted": len(entries),
            "faps_dropped": len(dropped),
        },
    }
    files = {
        "manifest.json": json.dumps(manifest, separators=(",", ":")).encode(),
        "portrait.png": _png(sheet.portrait),
        "mouth.png": _png(sheet.mouth),
        "data.bin": bytes(blob.buf),
        "stream.fap": sheet.stream_text.encode(),
    }
    return Package(manifest, files)


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
    raw = pkg.files["stream.fap"]
    seconds = pkg.manifest["stream"]["frames"] / pkg.manifest["stream"]["fps"]
    return {
        "stream_bytes": float(len(raw)),
        "stream_bytes_per_s": len(raw) / seconds,
        "stream_deflated_bytes_per_s": len(zlib.compress(raw, 9)) / seconds,
    }


def write(sheet: Fat2dSheet, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> bytes:
    """The package of a Fat2dSheet as zip bytes; sizes of its files and of the stream go into the report (fast:
    progress hears only its start)."""
    progress("package", 0.0)
    pkg = package(sheet)
    data = package_zip(pkg)
    report.sizes.update({name: len(b) for name, b in pkg.files.items()})
    report.figures.update({k: round(v, 1) for k, v in animation_sizes(pkg).items()})
    return data
