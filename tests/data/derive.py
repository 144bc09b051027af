"""Derive tests/data from the shared real-data folder: the small real files the tests read, with their licences.

    python tests/data/derive.py [SHARED_DATA_FOLDER]   (default ../shared/data)
    python tests/data/derive.py --check                 (verify tests/data against SHA256SUMS only)

Every file is copied byte for byte (same layout as ../shared/data, so a test can switch folders freely) and
listed in tests/data/SHA256SUMS. The full data sets (the 21 MB ICT FaceKit head) are not copied: tests that
need them use the `shared_data` fixture or the `shared` marker (see tests/conftest.py).
"""

from __future__ import annotations

import hashlib
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
DEFAULT_SOURCE = ROOT.parent / "shared" / "data"
XFACE_STREAMS = ("anger", "beg", "disgust", "fear", "happy-for", "hate", "joy", "pride")

FILES = (
    # Xface (FBK-irst): MPEG-4 FAP streams and the alice FDP, MPL-1.1 (header) / zlib-style setup licence.
    *(f"mpeg4/xface/{name}.fap" for name in XFACE_STREAMS),
    "mpeg4/xface/alice.fdp",
    "mpeg4/xface/mpl-header.txt",
    "mpeg4/xface/License_setup.txt",
    # MediaPipe canonical face model, Apache-2.0.
    "mediapipe_canonical/canonical_face_model.obj",
    "mediapipe_canonical/face_model_with_iris.obj",
    "mediapipe_canonical/LICENSE",
)
SUMS = HERE / "SHA256SUMS"


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def derive(source: Path) -> None:
    """Copy FILES from source into tests/data and rewrite SHA256SUMS."""
    lines = []
    for rel in FILES:
        dest = HERE / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(dest.name + ".tmp")
        shutil.copyfile(source / rel, tmp)
        tmp.replace(dest)
        lines.append(f"{sha256(dest)}  {rel}\n")
    SUMS.write_text("".join(lines), encoding="utf-8")
    total = sum((HERE / rel).stat().st_size for rel in FILES)
    print(f"tests/data: {len(FILES)} files, {total:,} bytes")


def check() -> list[str]:
    """Files whose bytes differ from SHA256SUMS (empty when tests/data is intact)."""
    bad = []
    for line in SUMS.read_text(encoding="utf-8").splitlines():
        digest, rel = line.split("  ", 1)
        path = HERE / rel
        if not path.is_file() or sha256(path) != digest:
            bad.append(rel)
    return bad


if __name__ == "__main__":
    if sys.argv[1:] == ["--check"]:
        problems = check()
        print("\n".join(problems) or "tests/data matches SHA256SUMS")
        sys.exit(1 if problems else 0)
    derive(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_SOURCE)
