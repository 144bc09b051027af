"""Input loaders: seconds to read each supported format into a FaceAnimation (bundled samples, ICT bench face)."""

from __future__ import annotations

import io
import statistics
import struct
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.faces import ict_bench_face
from converter.formats import load
from converter.formats.objseq import load_zip
from converter.formats.pointcache import load_obj_cache

TITLE = "Input formats: load times"
REPEATS = 5


def obj_text(frame: np.ndarray, faces: np.ndarray | None) -> bytes:
    """An OBJ of one frame (with triangles when given)."""
    out = io.StringIO()
    np.savetxt(out, frame, fmt="v %.5f %.5f %.5f")
    if faces is not None:
        np.savetxt(out, faces + 1, fmt="f %d %d %d")
    return out.getvalue().encode()


def median_seconds(fn) -> tuple[float, object]:
    """Median wall time of REPEATS calls, and the last result."""
    times, result = [], None
    for _ in range(REPEATS):
        t = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), result


def run() -> str:
    face = ict_bench_face()
    frames, faces = face.frames, face.faces
    rest = obj_text(frames[0], faces)
    pc2 = struct.pack("<12siiffi", b"POINTCACHE2\0", 1, face.n_vertices, 0.0, 1.0, face.n_frames)
    pc2 += frames.astype("<f4").tobytes()
    times = (np.arange(face.n_frames) / face.fps).astype(">f4")
    mdd = struct.pack(">ii", face.n_frames, face.n_vertices) + times.tobytes() + frames.astype(">f4").tobytes()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k in range(face.n_frames):
            zf.writestr(f"frame_{k:04d}.obj", rest if k == 0 else obj_text(frames[k], None))
    objzip = buf.getvalue()

    cases = [
        ("samples/face.glb (floats, sparse morph targets)", (ROOT / "samples/face.glb").stat().st_size,
         lambda: load(ROOT / "samples/face.glb")),
        ("samples/face_gltfpack.glb (quantized + meshopt)", (ROOT / "samples/face_gltfpack.glb").stat().st_size,
         lambda: load(ROOT / "samples/face_gltfpack.glb")),
        ("ICT bench face: OBJ + PC2", len(rest) + len(pc2), lambda: load_obj_cache(rest, pc2, name="pc2")),
        ("ICT bench face: OBJ + MDD", len(rest) + len(mdd), lambda: load_obj_cache(rest, mdd, name="mdd")),
        ("ICT bench face: zip of OBJ frames", len(objzip), lambda: load_zip(objzip, fps=face.fps, name="zip")),
    ]
    rows = ["| input | bytes | frames | vertices | triangles | load s (median of 5) | frames/s |",
            "|---|---:|---:|---:|---:|---:|---:|"]
    for label, size, fn in cases:
        secs, anim = median_seconds(fn)
        rows.append(f"| {label} | {size:,} | {anim.n_frames} | {anim.n_vertices:,} | {anim.n_faces:,} | "
                    f"{secs:.3f} | {anim.n_frames / secs:,.0f} |")
    return ("Wall time of `converter.formats` loaders from bytes in memory (files: read included) to a validated "
            "`FaceAnimation`, median of 5 runs. The ICT bench face is `bench.faces.ict_bench_face()` "
            f"({face.n_frames} frames, {face.n_faces:,} triangles) written by this script in each format; "
            "glTF times include node-hierarchy posing and morph-target blending for every frame.\n\n" + "\n".join(rows))


if __name__ == "__main__":
    print(run())
