"""What an uploaded file is, before converting it: a face (its clips, parts and nodes, morph targets, as
`facesvg info --json` lists them) or a take (its capture layout, frames and rate). The upload form's suggestions
and hints read it."""

from __future__ import annotations

import tempfile
from pathlib import Path

from converter import formats, framing
from converter.errors import InputError
from converter.formats import captures
from webapp.messages import with_user_names
from webapp.runner import morph_count
from webapp.uploads import check_main_input, stored_name

MAX_SUGGESTIONS = 200  # a datalist longer than this helps nobody (a 92-node avatar lists every bone)


def take_summary(path: Path, name: str) -> dict:
    """A take as `facesvg info` describes it; InputError (naming the user's file) if no layout reads it."""
    track = captures.parse_capture(path.read_bytes(), f"“{name}”")
    return {"kind": "take", "name": name, **captures.describe(track)}


def face_summary(path: Path, name: str, max_unzipped: int) -> dict:
    """A face's clips, what "Frame on part or node" accepts and its morph targets; InputError if unreadable."""
    kind = check_main_input(path, max_unzipped)
    out = {"kind": "face", "name": name, "input_kind": kind, "animations": [], "frame_on": [], "morph_targets": 0,
           "frames": None, "fps": None}
    if kind not in ("glb", "gltf"):  # OBJ/PLY frames and meshes: no clips or nodes to name; their parts come later
        return out
    anim = formats.load(path)
    clips = [{"index": int(c.get("index", i)), "name": str(c.get("name") or "")}
             for i, c in enumerate(anim.extras.get("animations") or ()) if isinstance(c, dict)]
    out.update(animations=clips, frame_on=framing.candidates(anim)[:MAX_SUGGESTIONS],
               morph_targets=morph_count(anim.extras.get("morph_targets")), frames=int(anim.n_frames),
               fps=float(anim.fps))
    return out


def inspect_upload(upload, max_unzipped: int, role: str = "") -> dict:
    """Describe an uploaded file (werkzeug FileStorage), kept only while it is read: as a take when role is
    "take", as a face when "face", else as what its content is; also names the layouts a take can be in.
    InputError names the user's file, never our temporary one."""
    name = (upload.filename or "upload").replace("\\", "/").rsplit("/", 1)[-1][:120]
    with tempfile.TemporaryDirectory(prefix="facesvg-inspect-") as folder:
        raw = Path(folder) / "upload.bin"
        upload.save(raw)
        if role == "take" or (role != "face" and captures.detect_file(raw) is not None):
            return take_summary(raw, name)
        with open(raw, "rb") as fh:
            head = fh.read(8192)
        stored = "upload.bin"
        try:
            stored = stored_name("input", name, formats.sniff(head) if head else None)
            summary = face_summary(raw.rename(Path(folder) / stored), name, max_unzipped)
        except InputError as exc:
            raise InputError(with_user_names(str(exc), {"input": stored}, {"input": name})) from None
    summary["driven_by"] = [layout.label for layout in captures.LAYOUTS]
    return summary
