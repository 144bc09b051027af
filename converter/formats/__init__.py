"""Input formats, recognised by content: glTF/GLB, a zip of OBJ/PLY frames (or mesh + point cache), OBJ or PLY
(+ PC2/MDD/.npy); formats users send that facesvg does not read are named with what to do."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from converter.animation import FaceAnimation, NonFinitePositions
from converter.errors import InputError
from converter.formats import gltf, objseq, ply, pointcache
from converter.formats.weights import is_capture
from converter.userfiles import read_bytes

MAX_INPUT_BYTES = 1 << 30


# Formats users send that facesvg does not read: (test on the first bytes, what it is and what to do).
BLENDER_GLTF = "export glTF 2.0 (.glb) from Blender (File > Export > glTF 2.0, with shape keys and animation)"
UNSUPPORTED: tuple[tuple[Callable[[bytes], bool], str], ...] = (
    (lambda d: d.startswith(b"Kaydara FBX Binary"), f"this is a binary FBX file, which facesvg does not read; "
     f"import it into Blender and {BLENDER_GLTF}"),
    (lambda d: b"FBXHeaderExtension" in d[:4096] or d.lstrip().startswith(b"; FBX"), "this is an ASCII FBX file, "
     f"which facesvg does not read; import it into Blender and {BLENDER_GLTF}"),
    (lambda d: d.startswith(b"PXR-USDC") or d.lstrip().startswith(b"#usda"), "this is a USD scene (.usd/.usda/.usdc), "
     f"which facesvg does not read; import it into Blender (File > Import > Universal Scene Description) and "
     f"{BLENDER_GLTF}"),
    (lambda d: d.lstrip().startswith(b"HIERARCHY"), "this is a BVH skeleton motion: it has joint angles but no mesh; "
     f"apply it to a rigged face in Blender and {BLENDER_GLTF}"),
    (lambda d: d.startswith(b"Ogawa"), "this is an Alembic (.abc) cache, which facesvg does not read; import it into "
     f"Blender and {BLENDER_GLTF}, or export the mesh as OBJ frames (zipped) or OBJ + PC2"),
    (lambda d: d.startswith(b"\x93NUMPY"), "this is a NumPy vertex array; give its template mesh (.ply/.obj) as the "
     "input and the array with --cache, or zip the template and the .npy together"),
)


def sniff(data: bytes) -> str:
    """The input kind from the first bytes: 'glb', 'gltf', 'zip', 'obj', 'ply', or raises InputError."""
    if data[:4] == b"glTF":
        return "glb"
    if data[:4] in (b"PK\x03\x04", b"PK\x05\x06"):
        if _first_zip_entry(data).lower().endswith((".usdc", ".usda", ".usd")):
            raise InputError("this is a USDZ scene, which facesvg does not read; import it into Blender (File > "
                             f"Import > Universal Scene Description) and {BLENDER_GLTF}.")
        return "zip"
    if data[:12] == b"POINTCACHE2\0":
        raise InputError("this is a PC2 point cache; give its OBJ mesh as the input and the cache with --cache.")
    if data[:4] in (b"ply\n", b"ply\r"):
        return "ply"
    for test, message in UNSUPPORTED:
        if test(data):
            raise InputError(message + ".")
    capture = is_capture(data)
    if capture:
        raise InputError(f"this is {capture}, not a face; give a face with morph targets as the input and pass the "
                         "capture with --weights.")
    head = data[:4096].removeprefix(b"\xef\xbb\xbf").lstrip()
    if head[:1] == b"{":
        return "gltf"
    text = head.decode("latin-1")
    if any(
        line.split(" ", 1)[0] in ("v", "f", "o", "g", "vt", "vn", "mtllib", "usemtl")
        for line in text.splitlines()[:200]
    ):
        return "obj"
    raise InputError("the input is not a glTF/GLB file, a zip of OBJ/PLY frames, an OBJ or a PLY mesh; check the file.")


def _first_zip_entry(data: bytes) -> str:
    """The name of a zip's first local entry ('' when unreadable): USDZ puts its .usdc/.usda first."""
    if data[:4] != b"PK\x03\x04" or len(data) < 30:
        return ""
    n = int.from_bytes(data[26:28], "little")
    return data[30:30 + n].decode("utf-8", errors="replace")


def check_gltf_document(data: bytes, name: str) -> None:
    """Refuse, with what it is, a JSON that is no glTF (a capture, other JSON) or a glTF that needs Draco."""
    if data[:4] != b"glTF":
        try:
            doc = json.loads(data.decode("utf-8-sig"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            return  # the glTF loader says the JSON is garbled
        if not isinstance(doc, dict) or "asset" not in doc:
            raise InputError(f"{name} is JSON but not a glTF document (it has no \"asset\"); give a glTF 2.0 file, "
                             "or pass a weight capture with --weights.")
    doc, _ = gltf.parse_container(data, name)
    if "KHR_draco_mesh_compression" in (doc.get("extensionsRequired") or []):
        raise InputError(f"{name} is Draco-compressed (KHR_draco_mesh_compression), which facesvg does not decode; "
                         "re-export it without Draco (Blender: uncheck Compression), or decompress it with "
                         "glTF-Transform or gltfpack.")


def load(path: str | Path, fps: float | None = None, cache: str | Path | None = None,
         animation: str | None = None) -> FaceAnimation:
    """Read any supported input file into a FaceAnimation (resampled to fps; animation picks a glTF clip)."""
    try:
        anim = _load(Path(path), fps, cache, animation)
    except NonFinitePositions as exc:  # raised where the frames are made: name the file(s) they came from
        names = Path(path).name + (f" with {Path(cache).name}" if cache is not None else "")
        raise InputError(f"{names}: {exc}") from None
    anim.extras.setdefault("source_path", str(path))  # lets 3D stages find side files such as NAME.fdp.json
    return anim


def _load(path: Path, fps: float | None, cache: str | Path | None, animation: str | None) -> FaceAnimation:
    data = read_bytes(path)
    if not data:
        raise InputError(f"{path.name} is empty.")
    kind = sniff(data)
    name = path.stem
    if kind in ("glb", "gltf"):
        check_gltf_document(data, path.name)
        return gltf.load_gltf(data, base_dir=path.parent, fps=fps, name=name, animation=animation)
    if animation is not None:
        raise InputError(f"--animation picks a glTF animation, and {path.name} is not glTF; leave it out.")
    if kind == "zip":
        return objseq.load_zip(data, fps=fps, name=name)
    if kind == "ply":
        still = ply.load_ply_static(data, fps=fps, name=name)
        return still if cache is None else pointcache.animate(still, read_bytes(cache, "point cache"), fps=fps)
    if cache is None:  # a mesh on its own: one frame (animate it with --cache FILE.pc2|.mdd)
        return pointcache.load_obj_static(data, fps=fps, name=name)
    return pointcache.load_obj_cache(data, read_bytes(cache, "point cache"), fps=fps, name=name)
