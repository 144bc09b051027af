"""SAiD (speech-driven blendshape diffusion, Park et al. 2024) coefficient CSV.

Layout (yunik1004/SAiD, script/inference.py writing said.util.blendshape.save_blendshape_coeffs, a pandas
`to_csv(index=False)`): a header of blendshape names, then one row of coefficients a frame, no time column, at the
model's 60 frames a second (inference.py's `--fps` default). The names are the 32 lower-face ARKit names of the
repo's data/ARKit_blendshapes.txt (jawForward ... noseSneerRight) in lowerCamel spelling.

Recognised only when every header cell is an ARKit blendshape name (any subset, in any order): a Live Link Face
CSV (Timecode, BlendShapeCount, capitalised names) or any CSV with a time column is another layout's.
"""

from __future__ import annotations

import csv
import io

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.arkit import NAME_SET
from converter.formats.captures.base import CaptureLayout, WeightTrack

WHAT = "SAiD blendshape coefficient CSV"
FPS = 60.0  # SAiD's inference --fps default: the rate of its BlendVOCA training data
SAID_NAMES = (  # data/ARKit_blendshapes.txt, the columns SAiD writes
    "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft",
    "mouthRight", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft",
    "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight", "mouthRollLower", "mouthRollUpper",
    "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft",
    "mouthLowerDownRight", "mouthUpperUpLeft", "mouthUpperUpRight", "cheekPuff", "cheekSquintLeft",
    "cheekSquintRight", "noseSneerLeft", "noseSneerRight",
)


def _header(line: str) -> list[str]:
    return [c.strip().strip('"') for c in line.split(",")]


def sniff(data: bytes) -> bool:
    """True when the first line is a comma-separated list of distinct ARKit names and nothing else."""
    head = _util.head(data)
    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    try:
        cells = _header(first.decode("ascii"))
    except UnicodeDecodeError:
        return False
    return len(cells) >= 2 and len(set(cells)) == len(cells) and all(c in NAME_SET for c in cells)


def parse(data: bytes, name: str = "said.csv") -> WeightTrack:
    """A SAiD CSV as a WeightTrack: one row a frame at 60 fps, the header's names, weights as written."""
    rows = [r for r in csv.reader(io.StringIO(_util.text(data, name, WHAT))) if any(c.strip() for c in r)]
    if not rows:
        raise InputError(f"{name} holds no header and no frames; give the CSV SAiD wrote.")
    header = [c.strip() for c in rows[0]]
    unknown = [c for c in header if c not in NAME_SET]
    if unknown:
        raise InputError(f"{name}: header cell {unknown[0][:30]!r} is not an ARKit blendshape name; a {WHAT} has "
                         "only blendshape names (no time column).")
    if len(set(header)) != len(header):
        dup = next(c for c in header if header.count(c) > 1)
        raise InputError(f"{name}: the header lists {dup!r} twice.")
    body = rows[1:]
    if not body:
        raise InputError(f"{name} has a header but no frames.")
    _util.frame_count(len(body), name)
    bad = next((k for k, r in enumerate(body) if len(r) != len(header)), None)
    if bad is not None:
        raise InputError(f"{name} row {bad + 2} has {len(body[bad])} cells but the header has {len(header)}; "
                         "the file is truncated or edited.")
    try:
        table = np.array(body, dtype=np.float64)
    except ValueError:
        k, j = next((k, j) for k, r in enumerate(body) for j, c in enumerate(r) if not _is_number(c))
        raise InputError(f"{name} row {k + 2}, column {header[j]}: {body[k][j][:30]!r} is not a number.") from None
    if not np.isfinite(table).all():
        k, j = np.argwhere(~np.isfinite(table))[0]
        raise InputError(f"{name} row {k + 2}, column {header[j]} is NaN or infinite.")
    return WeightTrack(header, np.arange(len(table)) / FPS, table.astype(np.float32), FPS, source=LAYOUT.name)


def _is_number(cell: str) -> bool:
    try:
        float(cell)
        return True
    except ValueError:
        return False


LAYOUT = CaptureLayout(
    name="said-csv",
    label="SAiD blendshape coefficients CSV",
    extensions=(".csv",),
    sniff=sniff,
    parse=parse,
    doc="yunik1004/SAiD script/inference.py output (pandas CSV: ARKit lower-face names header, 60 fps rows)",
)
