"""Derive the Live Link Face, MediaPipe and iFacialMocap fixtures of tests/data/captures from the shared real files.

    python tests/data/captures/derive_real.py [SHARED_DATA_FOLDER]   (default ../shared/data)

- `livelinkface_myslate3_cut.csv`: the header and the first LLF_ROWS rows of real/livelinkface_MySlate_3.csv,
  bytes unchanged (JMTechArt/Pipeline-Examples, MIT: LICENSE-JMTechArt-MIT.txt).
- `mediapipe_blendshapes_people.json`, `mediapipe_blendshapes_flat.json`: byte copies (V-Sekai mediapipe-labeler,
  MIT: LICENSE-vsekai-mediapipe-labeler-MIT.txt; MediaPipe itself Apache-2.0).
- `ifacialmocap_frame.txt`, `ifacialmocap_frame_extra_key.txt`: byte copies (korewaChino/rust-ifacialmocap, MIT:
  LICENSE-rust-ifacialmocap-MIT.md).
Each licence file is copied beside the fixtures.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_SOURCE = HERE.parents[2].parent / "shared" / "data"
LLF, LLF_OUT, LLF_ROWS = "real/livelinkface_MySlate_3.csv", "livelinkface_myslate3_cut.csv", 24
COPIES = (
    "real/mediapipe_blendshapes_people.json",
    "real/mediapipe_blendshapes_flat.json",
    "real/ifacialmocap_frame.txt",
    "real/ifacialmocap_frame_extra_key.txt",
    "real/LICENSE-JMTechArt-MIT.txt",
    "real/LICENSE-vsekai-mediapipe-labeler-MIT.txt",
    "real/LICENSE-rust-ifacialmocap-MIT.md",
)


def llf_cut(data: bytes) -> bytes:
    """The header line and the first LLF_ROWS rows, line endings as written."""
    return b"".join(data.splitlines(keepends=True)[:1 + LLF_ROWS])


def derive(source: Path) -> None:
    """Write the cut and the copies into this folder."""
    (HERE / LLF_OUT).write_bytes(llf_cut((source / LLF).read_bytes()))
    for rel in COPIES:
        (HERE / Path(rel).name).write_bytes((source / rel).read_bytes())
    print(f"{LLF_OUT} ({LLF_ROWS} rows) and {len(COPIES)} copies")


if __name__ == "__main__":
    derive(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_SOURCE)
