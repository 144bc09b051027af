"""Make the bundled FDPs: samples/ict.fdp.json, samples/mediapipe.fdp.json and samples/face.fdp.json.

    .venv/bin/python samples/make_fdp.py [SHARED_DATA_FOLDER]   (default ../shared/data)

ict.fdp.json: the ICT FaceKit neutral head's 68 Multi-PIE landmark vertex ids mapped to MPEG-4 feature points,
the rest by geometric rules, parts from the FaceKit README's vertex ranges (samples/ict_fdp.py).
mediapipe.fdp.json: the MediaPipe canonical face with irises (478 vertices), from known vertex ids.
face.fdp.json: the ICT FDP mapped onto samples/face.glb (same ICT coordinates, decimated) by nearest vertices.
Deterministic.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from converter import formats
from converter.formats.ictfacekit import load_ict_head
from converter.mpeg4.facepoints import mediapipe_fdp, transfer_fdp
from converter.mpeg4.fdp import save_fdp
from samples.ict_fdp import ict_fdp


def main(data: Path) -> None:
    ict = ict_fdp(data / "ict_facekit")
    save_fdp(ict, ROOT / "samples" / "ict.fdp.json")
    save_fdp(mediapipe_fdp(data / "mediapipe_canonical" / "face_model_with_iris.obj"),
             ROOT / "samples" / "mediapipe.fdp.json")
    sample = ROOT / "samples" / "face.glb"
    if sample.exists():
        head = load_ict_head(data / "ict_facekit")
        save_fdp(transfer_fdp(ict, head.vertices, formats.load(sample)), ROOT / "samples" / "face.fdp.json")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "data")
