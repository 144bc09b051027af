"""Every capture layout read and driven: frames, rate and duration as the take recorded them, against the output's.

For each capture (the real files in ../shared/data/real and the fixtures in tests/data/captures): the layout the
registry recognised, the frames, rate and duration it read, and the duration of the animation it drives on the
Ready Player Me avatar (52 ARKit morph targets), which must equal the take's. Plus the case a user hit: a 30 fps
Live Link Face take written with 60 fps timecodes (two timecode frames a row).
"""

from __future__ import annotations

import csv
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from converter import blendshapes
from converter.errors import InputError
from converter.formats import captures
from converter.formats.morphs import load_morph_face

TITLE = "Capture layouts: read at the times the take recorded (issue 53)"
REAL = ROOT.parent / "shared" / "data" / "real"
FIXTURES = ROOT / "tests" / "data" / "captures"
AVATAR = REAL / "rpm_template_xr.glb"
LONG_ROWS = 4030  # the user's 2 min 14 s take


def two_frames_a_row(path: Path, rows: int) -> float:
    """A Live Link Face CSV at 30 fps with 60 fps timecodes (FF steps by 2, as the user's take); its duration s."""
    with open(REAL / "livelinkface_MySlate_3.csv", newline="") as fh:
        header = next(csv.reader(fh))
    w = 0.5 + 0.5 * np.sin(np.arange(rows)[:, None] / 20.0 + np.arange(len(header) - 2)[None])
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(header)
        for i in range(rows):
            f = 31 + 2 * i  # 13:13:04:31, :33, :35, ... of a 60 fps timecode
            s = 13 * 3600 + 13 * 60 + 4 + f // 60
            out.writerow([f"{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}:{f % 60:02d}.652", len(header) - 2,
                          *(f"{x:.6f}" for x in 0.3 * w[i])])
    return rows / 30.0


def files() -> list[Path]:
    """Every capture file: the real ones, then the committed fixtures."""
    real = [p for p in sorted(REAL.glob("*")) if p.suffix.lower() in captures.extensions()
            and captures.detect_file(p) is not None]
    fixtures = [p for p in sorted(FIXTURES.glob("*")) if p.suffix.lower() in captures.extensions()
                and not p.name.startswith("LICENSE") and p.name != "README.md"]
    return real + fixtures


def row(face, path: Path, label: str, expected: float | None = None) -> str:
    """One table row: layout, frames, rate, duration read, driven frames and their duration."""
    c = time.process_time()
    try:
        track = captures.read_capture(path)
    except InputError as exc:
        return f"| {label} | refused: {exc} | | | | | | |"
    read = time.process_time() - c
    anim = blendshapes.drive(face, track)
    driven = anim.n_frames / anim.fps
    take = expected if expected is not None else track.duration
    layout = captures.describe(track)["layout"]
    return (f"| {label} | {layout} | {track.n_frames:,} | {track.fps:g} | {track.duration:.2f} | {read:.2f} | "
            f"{anim.n_frames:,} at {anim.fps:g} fps = {driven:.2f} s | {driven - take:+.3f} |")


def run() -> str:
    if not AVATAR.exists():
        return "Not measured: ../shared/data/real is missing."
    face = load_morph_face(AVATAR)
    rows = ["| capture | layout | frames | fps | take s | read CPU s | driven | driven - take s |",
            "|---|---|---:|---:|---:|---:|---|---:|"]
    for path in files():
        where = "real" if path.parent == REAL else "fixture"
        rows.append(row(face, path, f"{path.name} ({where})"))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "two_frames_a_row.csv"
        take = two_frames_a_row(path, LONG_ROWS)
        rows.append(row(face, path, f"{LONG_ROWS:,} rows, 30 fps, 60 fps timecodes (generated)", take))
    return ("Each capture read by `converter.formats.captures.read_capture` (the layout recognised by content) and "
            "driven onto the Ready Player Me avatar (`blendshapes.drive`, no --fps: the take's own rate). 'take s' "
            "is the take's duration as recorded (last time + one frame); 'driven - take' must be within a frame. "
            "Before this issue the generated 4,030-row take was driven one frame a row at the timecode's 60 fps: "
            "67.17 s for a 134.33 s take.\n\n" + "\n".join(rows))


if __name__ == "__main__":
    print(run())
