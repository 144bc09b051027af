"""Spine figures (issue 2): frames, triangles, seconds for load / extract / write, output bytes."""

from __future__ import annotations

import statistics
import struct
import time
from pathlib import Path

TITLE = "Spine: load, extract, write (issue 2)"
ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"
REPEATS = 3


def write_obj_pc2(anim, stem: Path) -> tuple[Path, Path]:
    """The bench face as OBJ + PC2 so its load time is measured through a real loader."""
    obj = stem.with_suffix(".obj")
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in anim.frames[0]]
    names = [p.name for p in anim.parts]
    for pid in range(len(names)):
        lines.append(f"usemtl {names[pid]}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in anim.faces[anim.part_ids == pid]]
    obj.write_text("\n".join(lines) + "\n")
    pc2 = stem.with_suffix(".pc2")
    header = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, anim.n_vertices, 0.0, 1.0, anim.n_frames)
    pc2.write_bytes(header + anim.frames.astype("<f4").tobytes())
    return obj, pc2


def measure(path: Path, cache: Path | None, label: str, stem: str) -> list[str]:
    """Median seconds over REPEATS for load, extract and write of one input with default options."""
    from converter import convert as conv
    from converter.options import ConversionOptions

    options = ConversionOptions()
    loads, extracts, writes = [], [], []
    result = None
    for _ in range(REPEATS):
        t = time.perf_counter()
        anim = conv.load(path, options, cache=cache)
        loads.append(time.perf_counter() - t)
        result = conv.convert_animation(anim, options)
        extracts.append(result.report.timings.get("extract", 0.0))
        writes.append(result.report.timings.get("write", 0.0))
    c = result.report.counts
    (OUT / f"spine_{stem}.svg").write_bytes(result.data)
    return [
        label,
        str(c["frames"]),
        f"{c['triangles']:,} ({c['triangles_kept']:,} kept)",
        f"{statistics.median(loads):.2f}",
        f"{statistics.median(extracts):.2f}",
        f"{statistics.median(writes):.2f}",
        f"{len(result.data):,}",
    ]


def run() -> str:
    """Markdown table for the bundled sample and the >= 5,000-triangle ICT bench face."""
    import sys

    sys.path.insert(0, str(ROOT / "bench"))
    from faces import ict_bench_face

    OUT.mkdir(parents=True, exist_ok=True)
    rows = [measure(ROOT / "samples" / "face.glb", None, "sample (samples/face.glb)", "sample")]
    obj, pc2 = write_obj_pc2(ict_bench_face(), OUT / "ict_bench")
    rows.append(measure(obj, pc2, "ICT bench face (OBJ + PC2)", "ict"))
    head = "| input | frames | triangles | load s | extract s | write s | SVG bytes |\n|---|---|---|---|---|---|---|\n"
    body = "\n".join("| " + " | ".join(r) + " |" for r in rows)
    return (
        f"Default options (512 px, tolerance 0.25 px, occlusion on); medians of {REPEATS} runs. Extract includes "
        "the projection of every frame, culling, the triangle-id occlusion render of every frame (on the CPU, "
        "converter.raster) and "
        "shading; write is the SVG encoder.\n\n" + head + body
    )
