"""Input formats, recognised by content: glTF/GLB, a zip of OBJ frames (or OBJ + point cache), OBJ + PC2/MDD."""

from __future__ import annotations

from pathlib import Path

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.userfiles import read_bytes

MAX_INPUT_BYTES = 1 << 30


def sniff(data: bytes) -> str:
    """The input kind from the first bytes: 'glb', 'gltf', 'zip', 'obj', or raises InputError."""
    if data[:4] == b"glTF":
        return "glb"
    if data[:4] in (b"PK\x03\x04", b"PK\x05\x06"):
        return "zip"
    if data[:12] == b"POINTCACHE2\0":
        raise InputError("this is a PC2 point cache; give its OBJ mesh as the input and the cache with --cache.")
    head = data[:4096].removeprefix(b"\xef\xbb\xbf").lstrip()
    if head[:1] == b"{":
        return "gltf"
    text = head.decode("latin-1")
    if any(line.split(" ", 1)[0] in ("v", "f", "o", "g", "vt", "vn", "mtllib", "usemtl") for line in text.splitlines()[:200]):
        return "obj"
    raise InputError("the input is not a glTF/GLB file, a zip of OBJ frames, or an OBJ mesh; check the file.")


def load(path: str | Path, fps: float | None = None, cache: str | Path | None = None,
         animation: str | None = None) -> FaceAnimation:
    """Read any supported input file into a FaceAnimation (resampled to fps; animation picks a glTF clip)."""
    anim = _load(Path(path), fps, cache, animation)
    anim.extras.setdefault("source_path", str(path))  # lets 3D stages find side files such as NAME.fdp.json
    return anim


def _load(path: Path, fps: float | None, cache: str | Path | None, animation: str | None) -> FaceAnimation:
    data = read_bytes(path)
    if not data:
        raise InputError(f"{path.name} is empty.")
    kind = sniff(data)
    name = path.stem
    if kind in ("glb", "gltf"):
        from converter.formats import gltf

        return gltf.load_gltf(data, base_dir=path.parent, fps=fps, name=name, animation=animation)
    if animation is not None:
        raise InputError(f"--animation picks a glTF animation, and {path.name} is not glTF; leave it out.")
    if kind == "zip":
        from converter.formats import objseq

        return objseq.load_zip(data, fps=fps, name=name)
    from converter.formats import pointcache

    if cache is None:  # a mesh on its own: one frame (animate it with --cache FILE.pc2|.mdd)
        return pointcache.load_obj_static(data, fps=fps, name=name)
    return pointcache.load_obj_cache(data, read_bytes(cache, "point cache"), fps=fps, name=name)
