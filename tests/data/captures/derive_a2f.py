"""Cut tests/data/captures/a2f_charlie_cut.json from the real Audio2Face export in the shared data folder.

    python tests/data/captures/derive_a2f.py [SHARED_DATA_FOLDER]   (default ../shared/data)

Frames START .. START + COUNT of real/a2f_charlie_bsweight.json (around the take's widest jaw opening), every key
kept in the export's order and values unchanged; numFrames says the cut's length. The export is by Lucas
Matuszewski (LucasMatuszewski/3d-ai-avatar-babylonjs, src/assets/a2f/), ISC (LICENSE-a2f-charlie-ISC-package.json).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_SOURCE = HERE.parents[2].parent / "shared" / "data"
SOURCE = "real/a2f_charlie_bsweight.json"
LICENCE = "real/LICENSE-a2f-charlie-ISC-package.json"
OUT = HERE / "a2f_charlie_cut.json"
START, COUNT = 600, 8
PER_FRAME = ("weightMat", "rotations", "translations")


def cut(doc: dict) -> dict:
    """The export with only frames START .. START + COUNT."""
    out = dict(doc)
    for key in PER_FRAME:
        out[key] = doc[key][START:START + COUNT]
    out["numFrames"] = COUNT
    return out


def derive(source: Path) -> None:
    """Write the cut and copy the licence beside it."""
    doc = json.loads((source / SOURCE).read_text(encoding="utf-8"))
    OUT.write_text(json.dumps(cut(doc), indent=4) + "\n", encoding="utf-8")
    (HERE / Path(LICENCE).name).write_bytes((source / LICENCE).read_bytes())
    print(f"{OUT.name}: {COUNT} frames, {OUT.stat().st_size:,} bytes")


if __name__ == "__main__":
    derive(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_SOURCE)
