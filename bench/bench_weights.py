"""ARKit weight captures driving a face: names matched on the ICT head, and a 4,000-frame capture's cost.

The 4,000-frame run happens in a child process so its peak RSS is its own (ru_maxrss of the child).
"""

from __future__ import annotations

import csv
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from converter import blendshapes
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights

TITLE = "ARKit weight captures on the ICT head"
ICT = ROOT.parent / "shared" / "data" / "ict_facekit"
LLF = ROOT.parent / "shared" / "data" / "real" / "livelinkface_MySlate_3.csv"
LONG_FRAMES = 4000


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
                      "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "frames_mb": anim.frames.nbytes / 2 ** 20}))


def run() -> str:
    face = load_morph_face(ICT)
    track = read_weights(LLF)
    anim = blendshapes.drive(face, track)
    c = anim.extras["weights"]["counts"]
    out = subprocess.run([sys.executable, __file__, "--child", str(LONG_FRAMES)], capture_output=True, text=True,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
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
    ])


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        child(int(sys.argv[2]))
    else:
        print(run())
