"""ARKit weight captures driving a face: names matched on the ICT head, and a 4,000-frame capture's cost.

The 4,000-frame run happens in a child process so its peak RSS is its own (the child's VmHWM, bench/usage.py).
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import usage
from converter import blendshapes
from converter.convert import convert
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions

TITLE = "ARKit weight captures on the ICT head"
ICT = ROOT.parent / "shared" / "data" / "ict_facekit"
LLF = ROOT.parent / "shared" / "data" / "real" / "livelinkface_MySlate_3.csv"
LONG_FRAMES = 4000
# End to end (`facesvg convert ICT --weights long.csv`): the mobile preset's options and the defaults.
CONVERT_RUNS = (("mobile preset (1,500 triangles, 256 px)", {"max_triangles": 1500, "size": 256}), ("defaults", {}))


def write_capture(path: Path, n_frames: int) -> None:
    """A Live Link Face CSV with the take's 52 columns and 9 angles, n_frames at 60 fps (weights: slow sines)."""
    with open(LLF, newline="") as fh:
        header = next(csv.reader(fh))
    k = np.arange(n_frames)[:, None]
    w = 0.5 + 0.5 * np.sin(k / 30.0 + np.arange(len(header) - 2)[None])
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(header)
        for i in range(n_frames):
            s = i // 60
            out.writerow([f"01:{s // 60:02d}:{s % 60:02d}:{i % 60:02d}.000", len(header) - 2,
                          *(f"{x:.6f}" for x in 0.2 * w[i])])


def child(n_frames: int) -> None:
    """Run in the child: load the head, read the capture, drive it; print one JSON line of figures."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.csv"
        write_capture(path, n_frames)
        c0, t0 = time.process_time(), time.perf_counter()
        face = load_morph_face(ICT)
        c1 = time.process_time()
        track = read_weights(path)
        c2 = time.process_time()
        anim = blendshapes.drive(face, track)
        c3, t3 = time.process_time(), time.perf_counter()
    print(json.dumps({"frames": anim.n_frames, "vertices": anim.n_vertices, "load_cpu": c1 - c0,
                      "read_cpu": c2 - c1, "drive_cpu": c3 - c2, "wall": t3 - t0,
                      "rss_mb": usage.own_peak_mb(),
                      "frames_mb": anim.frames.nbytes / 2 ** 20}))


def child_convert(n_frames: int, options: dict) -> None:
    """Run in the child: the whole conversion of the head driven by an n_frames capture; one JSON line."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.csv"
        write_capture(path, n_frames)
        c0, t0 = usage.cpu(), time.perf_counter()
        result = convert(ICT, ConversionOptions.from_mapping({**options, "weights": str(path)}))
        c1, t1 = usage.cpu(), time.perf_counter()
    r = result.report
    print(json.dumps({"cpu": c1 - c0, "wall": t1 - t0, "rss_mb": usage.peak_mb(),
                      "bytes": len(result.data), "triangles": r.counts.get("paths", 0),
                      "timings": {k: round(v, 1) for k, v in r.timings.items()}}))


def run() -> str:
    face = load_morph_face(ICT)
    track = read_weights(LLF)
    anim = blendshapes.drive(face, track)
    c = anim.extras["weights"]["counts"]
    out = subprocess.run([sys.executable, __file__, "--child", str(LONG_FRAMES)], capture_output=True, text=True,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    rows = []
    for label, opts in CONVERT_RUNS:
        got = subprocess.run([sys.executable, __file__, "--convert", str(LONG_FRAMES), json.dumps(opts)],
                             capture_output=True, text=True)
        if got.returncode:
            rows.append(f"| {label} | failed: {(got.stderr.strip().splitlines() or ['?'])[-1][:120]} | | | | |")
            continue
        e = json.loads(got.stdout.strip().splitlines()[-1])
        rows.append(f"| {label} | {e['cpu']:.0f} | {e['wall']:.0f} | {e['rss_mb']:,.0f} | {e['triangles']:,} paths, "
                    f"{e['bytes'] / 2 ** 20:.1f} MB | {', '.join(f'{k} {v:g}' for k, v in e['timings'].items())} |")
    return "\n".join([
        f"Live Link Face take `{LLF.name}` ({track.n_frames} frames, {track.fps:g} fps, {len(track.names)} weights) "
        f"on the ICT FaceKit head ({len(face.names)} ARKit-named shapes):",
        "",
        "| weights matched | weights unmatched | shapes driven | shapes undriven | head rotation | eye rotation |",
        "|---|---|---|---|---|---|",
        f"| {c['weights_matched']} | {c['weights_unmatched']} | {c['targets_driven']} | {c['targets_undriven']} | "
        f"{'applied' if c['head_rotation_applied'] else 'none (angles all 0)'} | "
        f"{'applied to both eyeballs' if c['eye_rotation_applied'] else 'no'} |",
        "",
        f"A generated {r['frames']}-frame Live Link Face CSV (all 52 weights, 60 fps) driving the full head "
        f"({r['vertices']} vertices), the 3D stage only (load + read + drive, one child process):",
        "",
        "| frames | CPU s: load head | CPU s: read CSV | CPU s: drive | wall s | peak RSS MB | frames array MB |",
        "|---|---|---|---|---|---|---|",
        f"| {r['frames']} | {r['load_cpu']:.1f} | {r['read_cpu']:.1f} | {r['drive_cpu']:.1f} | {r['wall']:.1f} | "
        f"{r['rss_mb']:.0f} | {r['frames_mb']:.0f} |",
        "",
        f"The whole conversion (`facesvg convert ICT --weights long.csv`, {LONG_FRAMES} frames) in one child process "
        "each (wall s: the stage timings are wall seconds on a shared machine):",
        "",
        "| options | CPU s | wall s | peak RSS MB | output | stage wall s |",
        "|---|---|---|---|---|---|",
        *rows,
    ])


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        child(int(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "--convert":
        child_convert(int(sys.argv[2]), json.loads(sys.argv[3]))
    else:
        print(run())
