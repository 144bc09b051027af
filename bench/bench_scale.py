"""Conversion speed and memory at scale (issue 16): CPU seconds and peak RSS, beside a naive writer.

Each case converts in a fresh child process (so its peak RSS is its own) with the default options: the
capture-like face (bench/capture_like.py) and its longer and denser variants. Longer: the same generator with
more frames. Denser: the 8k-triangle face split 1 -> 4 by edge midpoints (32k), twice (128k); the 2k face is
the generator's own simplification. The naive writer (``naive_svg``, in its own child, after the same
extraction) streams every kept triangle's coordinates at every frame with 2 decimals, formatted a block of
paths at a time. ``--raw`` (the chapter's unoptimised file: the same values plus colour and visibility
animations) is measured too, up to 1,000 frames: it is also written a block of paths at a time, so its peak
follows its output (it held every string of the file at once until today: 1.3 GB at 8k x 100 frames, 4.2 GB at
8k x 335).

FACESVG_BENCH_QUICK=1 runs only up to 1,000 frames and 32k triangles (the big cases cost minutes each).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench import usage
from bench.bench_weights import ICT, write_capture
from bench.capture_like import FRAMES, capture_like
from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation, extract_sheet, load
from converter.encode import parallel
from converter.formats import load as load_file
from converter.options import ConversionOptions, Report
from converter.outputs import output_kind

TITLE = "Conversion speed and memory (issue 16)"
QUICK = os.environ.get("FACESVG_BENCH_QUICK", "") not in ("", "0")
CAPTURE = (FRAMES, 8000, 0)  # the capture-like face (bench/capture_like.py): the headline case
# (frames, generator triangles, midpoint subdivisions)
FRAME_CASES = ((100, 8000, 0), (FRAMES, 8000, 0), (1000, 8000, 0), (3000, 8000, 0))
TRIANGLE_CASES = ((FRAMES, 2000, 0), (FRAMES, 8000, 0), (FRAMES, 8000, 1), (FRAMES, 8000, 2))
MEDIAN_CASES = (CAPTURE, (3000, 8000, 0), (FRAMES, 8000, 2))  # the cases with a CPU target: each mode's median
MEDIAN_RUNS = 3  # run by CPU of this many (single runs on this shared host scatter by 10-20 %); the others run once
QUICK_FRAMES, QUICK_TRIANGLES = 1000, 40000
ARKIT = (4000, -1, 0)  # the ICT head (full, 50,996 triangles) driven by a 4,000-frame Live Link Face capture
RAW_FRAMES = 1000  # --raw is measured up to this many frames (its file is ~0.35 GB at 1,000)
TARGETS = "capture-like <= 7 s CPU and <= 350 MB; writer >= 1 M triangle-frames/s; 8k x 3,000 <= 60 s and " \
          "<= 2.5 GB; 128k x 336 <= 80 s and <= 4 GB; peak RSS <= 100 B per triangle-frame"


def subdivided(anim: FaceAnimation, times: int) -> FaceAnimation:
    """The animation with every triangle split into 4 at its edge midpoints, `times` times (parts kept)."""
    if times == 0:
        return anim
    frames, faces, part_ids = anim.frames, anim.faces, anim.part_ids
    for _ in range(times):
        v = frames.shape[1]
        edges = np.sort(np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1), axis=2)
        uniq, inv = np.unique(edges.reshape(-1, 2), axis=0, return_inverse=True)
        mid = (frames[:, uniq[:, 0]] + frames[:, uniq[:, 1]]) * np.float32(0.5)
        frames = np.concatenate([frames, mid], axis=1)
        m = (v + inv.reshape(-1, 3)).astype(np.int32)  # midpoints of edges 01, 12, 20
        a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
        faces = np.concatenate([np.column_stack([a, m[:, 0], m[:, 2]]), np.column_stack([m[:, 0], b, m[:, 1]]),
                                np.column_stack([m[:, 2], m[:, 1], c]), m]).astype(np.int32)
        part_ids = np.tile(part_ids, 4)
    return FaceAnimation(frames, faces, part_ids, anim.parts, anim.fps, f"{anim.name}_x{4 ** times}",
                         extras=dict(anim.extras))


def face(frames: int, triangles: int, subdivisions: int) -> FaceAnimation:
    """One benchmark face: the capture-like generator, then midpoint subdivisions."""
    return subdivided(capture_like(n_frames=frames, triangles=triangles), subdivisions)


FACE_CACHE = ROOT / "bench" / "out" / "faces"


def face_file(frames: int, triangles: int, subdivisions: int) -> Path:
    """The benchmark face saved once, by a process of its own (keyed by the generators' source), so that a
    measured child loads it as the CLI loads a file instead of also holding the generator's heap (the ICT head
    and its morph targets, its float64 intermediates) in its peak RSS."""
    src = b"".join((ROOT / "bench" / n).read_bytes() for n in ("capture_like.py", "faces.py", "bench_scale.py"))
    path = FACE_CACHE / f"face_{frames}_{triangles}_{subdivisions}_{hashlib.sha1(src).hexdigest()[:10]}.npz"
    if not path.exists():
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "face", str(frames), str(triangles),
                        str(subdivisions), str(path)], cwd=ROOT, check=True)
    return path


def save_face(frames: int, triangles: int, subdivisions: int, path: Path) -> None:
    """Generate one benchmark face and write it to path (atomically)."""
    anim = face(frames, triangles, subdivisions)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as f:
        np.savez(f, frames=anim.frames, faces=anim.faces, part_ids=anim.part_ids, fps=anim.fps,
                 meta=json.dumps({"name": anim.name, "parts": [[p.name, list(p.color), p.label] for p in anim.parts],
                                  "extras": anim.extras}))
    os.replace(tmp, path)


def load_face(path: Path) -> FaceAnimation:
    """A face saved by save_face."""
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        parts = tuple(Part(n, tuple(c), label) for n, c, label in meta["parts"])
        return FaceAnimation(z["frames"], z["faces"], z["part_ids"], parts, float(z["fps"]), meta["name"],
                             extras=meta["extras"])


def arkit_face(frames: int) -> FaceAnimation:
    """The ICT FaceKit head driven by a generated Live Link Face capture of `frames` frames (bench_weights'
    write_capture: all 52 weights and the head and eye angles), loaded as `facesvg convert ICT --weights` loads it."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "capture.csv"
        write_capture(path, frames)
        return load(ICT, ConversionOptions(weights=str(path)))


def naive_svg(sheet, sink, block: int = 256) -> int:
    """The naive animated SVG of a Sheet into sink(bytes): per kept triangle one path whose d holds every frame's
    coordinates with 2 decimals (frame 0's fill); returns the bytes written."""
    t = sheet.n_frames
    dur = f"{sheet.duration:.3f}s"
    rgb = np.zeros((len(sheet.faces), 3), np.int64)  # per triangle id (the kept ones; no other is drawn)
    rgb[sheet.kept] = np.clip(np.rint(sheet.face_rgb[0] * 255), 0, 255).astype(np.int64)
    n = sink(f'<svg xmlns="http://www.w3.org/2000/svg" width="{sheet.camera.width}" '
             f'height="{sheet.camera.height}">\n'.encode())
    tris = np.asarray(sheet.order)
    for a in range(0, len(tris), block):
        tb = tris[a:a + block]
        xy = np.round(sheet.xy[:, sheet.faces[tb]].reshape(t, len(tb), 6).astype(np.float64), 2)
        vals = (("M%.2f,%.2fL%.2f,%.2fL%.2f,%.2fZ;" * (t * len(tb))) % tuple(xy.transpose(1, 0, 2).ravel().tolist()))
        rows = vals.split("Z;")
        parts = []
        for j, tri in enumerate(tb.tolist()):
            d = "Z;".join(rows[j * t:(j + 1) * t]) + "Z"
            c = rgb[tri]
            parts.append(f'<path fill="#{c[0]:02x}{c[1]:02x}{c[2]:02x}" d="{rows[j * t]}Z"><animate attributeName="d" '
                         f'dur="{dur}" repeatCount="indefinite" values="{d}"/></path>\n')
        n += sink("".join(parts).encode())
    return n + sink(b"</svg>\n")


def child(frames: int, triangles: int, subdivisions: int, mode: str) -> dict:
    """Run in the child process: load the face (face_file), convert it (mode 'bounded', 'raw', or 'naive': the
    same extraction and naive_svg), report CPU (user+sys) and peak RSS."""
    if mode == "floor":  # the runtime's own share: the bundled sample's first 10 frames, converted
        anim = load_file(ROOT / "samples" / "face.glb").sliced(0, 10)
        c = usage.cpu()
        convert_animation(anim, ConversionOptions())
        return {"cpu": usage.cpu() - c, "peak_mb": usage.peak_mb()}
    anim = arkit_face(frames) if triangles == ARKIT[1] else load_face(face_file(frames, triangles, subdivisions))
    before_mb = usage.own_peak_mb()
    shape = {"triangles": anim.n_faces, "frames": anim.n_frames}
    handed = [anim]  # the face is handed over, as `facesvg convert` hands over what it loads: its frames go
    del anim  # once extracted (both modes)
    if mode == "naive":
        c = usage.cpu()
        sheet = extract_sheet(handed.pop(), ConversionOptions(), Report())
        w = usage.cpu()
        size = naive_svg(sheet, len)
        cpu = usage.cpu() - c
        return {**shape, "cpu": cpu, "writer_cpu": cpu - (w - c),
                "peak_mb": usage.peak_mb(), "before_mb": before_mb,
                "bytes": size}
    kind = output_kind("svg")
    flat = kind.shading_writers["flat"]
    writer_cpu = [0.0]

    def timed(*args, **kwargs):
        c = time.process_time()
        out = flat(*args, **kwargs)
        writer_cpu[0] = time.process_time() - c
        return out

    kind.shading_writers["flat"] = timed
    c, w = usage.cpu(), time.perf_counter()
    result = convert_animation(handed.pop(), ConversionOptions(raw=mode == "raw"))
    cpu, wall = usage.cpu() - c, time.perf_counter() - w
    return {**shape, "cpu": cpu, "wall": wall, "writer_cpu": writer_cpu[0],
            "extract_cpu": cpu - writer_cpu[0], "peak_mb": usage.peak_mb(),
            "before_mb": before_mb, "bytes": len(result.data), "md5": hashlib.md5(result.data).hexdigest(),
            "paths": result.report.counts.get("paths", 0)}


def measure(frames: int, triangles: int, subdivisions: int, mode: str, threads: int | None = None) -> dict:
    """child(...) in a fresh interpreter (the face is generated first, in a process of its own), its kernels on
    threads threads (default: the converter's own choice)."""
    if mode != "floor" and triangles != ARKIT[1]:
        face_file(frames, triangles, subdivisions)
    cmd = [sys.executable, str(Path(__file__).resolve()), "child", str(frames), str(triangles), str(subdivisions),
           mode]
    env = dict(os.environ, PYOPENGL_PLATFORM=os.environ.get("PYOPENGL_PLATFORM", "egl"))
    env.pop(parallel.ENV, None)
    if threads is not None:
        env[parallel.ENV] = str(threads)
    out, tree_mb = usage.run_measured(cmd, env=env, cwd=ROOT)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    r["rss_peak_mb"], r["peak_mb"] = r["peak_mb"], max(r["peak_mb"], tree_mb)
    return r


def _median(runs: list[dict]) -> dict:
    """The run with the median convert CPU."""
    return sorted(runs, key=lambda r: r["cpu"])[len(runs) // 2]


def _exponent(x: list[float], y: list[float]) -> str:
    if len(x) < 2:
        return "n/a"
    return f"{np.polyfit(np.log(x), np.log(y), 1)[0]:.2f}"


def run() -> str:
    frame_cases = [c for c in FRAME_CASES if not QUICK or c[0] <= QUICK_FRAMES]
    tri_cases = [c for c in TRIANGLE_CASES if not QUICK or c[1] * 4 ** c[2] <= QUICK_TRIANGLES]
    cases = list(dict.fromkeys(frame_cases + tri_cases + ([] if QUICK else [ARKIT])))
    floor = _median([measure(0, 0, 0, "floor") for _ in range(3)])
    res = {}
    for case in cases:
        runs = MEDIAN_RUNS if case in MEDIAN_CASES else 1
        res[case] = tuple(_median([measure(*case, mode) for _ in range(runs)]) for mode in ("bounded", "naive"))
        print(case, res[case], flush=True)
    rows = ["| case | triangles x frames | CPU s (convert) | of which writer | writer M tri-frames/s | peak MB | "
            "B per tri-frame | naive CPU s | naive peak MB | CPU vs naive | output MB (naive) |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for case in cases:
        b, r = res[case]
        tf = b["triangles"] * b["frames"]
        label = ("capture-like face" if case == CAPTURE else f"ARKit-driven ICT head x {case[0]:,}" if case == ARKIT
                 else f"{case[1] * 4 ** case[2] // 1000}k x {case[0]}")
        label += f" (median of {MEDIAN_RUNS})" if case in MEDIAN_CASES else ""
        rows.append(f"| {label} | {b['triangles']:,} x {b['frames']:,} | {b['cpu']:.1f} | {b['writer_cpu']:.1f} | "
                    f"{tf / b['writer_cpu'] / 1e6:.2f} | {b['peak_mb']:,.0f} | {b['peak_mb'] * 2 ** 20 / tf:.0f} | "
                    f"{r['cpu']:.1f} | {r['peak_mb']:,.0f} | {b['cpu'] / r['cpu']:.2f} | "
                    f"{b['bytes'] / 1e6:.1f} ({r['bytes'] / 1e6:.1f}) |")
    raw_cases = [c for c in frame_cases if c[0] <= RAW_FRAMES]
    rows += ["", "`--raw`, a block of paths at a time:", "",
             "| case | CPU s | peak MB | B per tri-frame | output MB |", "|---|---|---|---|---|"]
    for case in raw_cases:
        r = measure(*case, "raw")
        tf = r["triangles"] * r["frames"]
        rows.append(f"| {case[1] // 1000}k x {case[0]} | {r['cpu']:.1f} | {r['peak_mb']:,.0f} | "
                    f"{r['peak_mb'] * 2 ** 20 / tf:.0f} | {r['bytes'] / 1e6:.1f} |")
    one = _median([measure(*CAPTURE, "bounded", threads=1) for _ in range(MEDIAN_RUNS)])
    rows += ["", f"Threads: the capture-like face with the kernels on {parallel.THREADS} threads (the default here) "
             f"and on one (`FACESVG_THREADS=1`), each the median run by CPU of {MEDIAN_RUNS}:", "",
             "| threads | CPU s | wall s | peak MB | same bytes |", "|---|---|---|---|---|"]
    for label, r in ((str(parallel.THREADS), res[CAPTURE][0]), ("1", one)):
        rows.append(f"| {label} | {r['cpu']:.1f} | {r['wall']:.1f} | {r['peak_mb']:,.0f} | "
                    f"{'yes' if r['md5'] == res[CAPTURE][0]['md5'] else 'NO'} |")
    fx = [res[c][0]["frames"] for c in frame_cases]
    tx = [res[c][0]["triangles"] for c in tri_cases]
    grow = (f"Growth exponents (log-log fit of convert CPU): frames {_exponent(fx, [res[c][0]['cpu'] for c in frame_cases])}"
            f" (8k triangles, {', '.join(map(str, fx))} frames); triangles "
            f"{_exponent(tx, [res[c][0]['cpu'] for c in tri_cases])} ({', '.join(f'{t:,}' for t in tx)} triangles). "
            f"Peak memory: frames {_exponent(fx, [res[c][0]['peak_mb'] for c in frame_cases])}, triangles "
            f"{_exponent(tx, [res[c][0]['peak_mb'] for c in tri_cases])}.")
    skipped = [c for c in FRAME_CASES + TRIANGLE_CASES if c not in cases]
    note = (f"Quick mode (FACESVG_BENCH_QUICK=1): not run: "
            f"{', '.join(f'{c[1] * 4 ** c[2] // 1000}k x {c[0]}' for c in skipped)}. " if skipped else "")
    return "\n".join([
        "Default options (flat, bounded, rigid factoring on, 512 px) against the naive writer (`naive_svg`: the same "
        "extraction, then every kept triangle's coordinates at every frame with 2 decimals, streamed). CPU is user+sys of the conversion inside a fresh child process (all "
        "threads, plus any process it forks: `bench/usage.py`; the face's generation excluded). The cases with a CPU target "
        f"(capture-like, 8k x 3,000, 128k) are each mode's median run by CPU of {MEDIAN_RUNS} (since 2026-12-06; before, "
        "the capture-like face's alone), the other cases one run each (the machine, 2 cores, was shared with other "
        "engineers' jobs: single runs scatter by 10-20 %). Peak MB is the larger of the child's high-water RSS (VmHWM; since 2026-12-07 not its `ru_maxrss`, which Linux starts at the spawning parent's size), any forked child's, and the "
        "sampled peak of the sum of their PSS (shared pages counted once, every 20 ms while a child lives: "
        "`usage.TreePss`; since 2026-12-06 not while the conversion runs alone, where reading its PSS took the bench "
        "a third of a core and contended with the conversion's page faults). The child loads its face from an .npz that a process of its "
        "own generated (until 2026-12-03 the child generated it, and its peak held the generator's heap too), so the "
        f"peak is the interpreter and libraries, the face's frames (~{res[cases[0]][0]['before_mb']:.0f} MB before "
        "converting at 100 frames) and the conversion. The child then hands the face over, as `facesvg convert` "
        "does with what it loads (it keeps no reference: the 3D frames go once extracted, before the writer; since "
        "2026-12-07, both modes). The runtime's own share: converting the bundled sample's first "
        f"10 frames peaks at {floor['peak_mb']:,.0f} MB (median of 3; numba's compiled code ~60 MB, measured 2026-12-03; "
        "no Mesa EGL context since 2026-12-06, when the occlusion pass moved to a child process, and none at all "
        "since its ids are rasterised on the CPU, `converter/raster.py`, 2026-12-06). Writer M tri-frames/s = triangles x frames / "
        "writer CPU.",
        "",
        *rows,
        "",
        grow,
        "",
        f"{note}ARKit-driven ICT head: the full ICT FaceKit head (26,719 vertices, 50,996 triangles, "
        f"{res[ARKIT][0]['paths']:,} of them ever seen and drawn) driven by a generated 4,000-frame Live Link Face "
        "CSV (bench_weights' "
        "`write_capture`: all 52 weights and the head and eye angles as slow sines, 60 fps), loaded as `facesvg "
        "convert ICT --weights capture.csv` loads it; its peak includes the loader's (head, capture, driven frames: "
        f"{res[ARKIT][0]['before_mb']:,.0f} MB before converting)." if ARKIT in res else note,
        f"Targets (issue 16): {TARGETS}.",
    ])


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "child":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        f, t, s, mode = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
        print(json.dumps(child(f, t, s, mode)))
    elif len(sys.argv) > 1 and sys.argv[1] == "face":
        save_face(int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), Path(sys.argv[5]))
    else:
        print(run())
