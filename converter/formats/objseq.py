"""A .zip of numbered OBJ or PLY frames (one topology), or of one mesh plus a .pc2/.mdd/.npy cache, to FaceAnimation.

The zip is read in memory and never extracted. Refused: entries with absolute paths or '..', symlinks,
encrypted entries, more than MAX_ENTRIES entries, more than MAX_TOTAL bytes uncompressed, or a compression
ratio above MAX_RATIO (a decompression bomb).
"""

from __future__ import annotations

import io
import math
import re
import stat
import zipfile
import zlib

import numpy as np

from converter.animation import DEFAULT_PART_COLORS, FaceAnimation, Part
from converter.errors import InputError
from converter.formats.obj import parse_obj, parse_obj_vertices
from converter.formats.parts import parts_for_groups
from converter.formats.ply import load_ply_static, read_ply
from converter.formats.pointcache import animate, load_obj_cache

DEFAULT_FPS = 30.0
MAX_ENTRIES = 20_000
MAX_TOTAL = 2 * 1024 ** 3
MAX_RATIO = 200
RATIO_MIN_BYTES = 1 << 20  # tiny entries may compress absurdly well (e.g. empty files); only judge big ones


def load_zip(data: bytes, fps: float | None = None, name: str = "face") -> FaceAnimation:
    """Frames from every .obj in natural name order (or OBJ + point cache), at fps (default 30)."""
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}.")
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, OSError, KeyError, NotImplementedError):
        raise InputError(f"{name} is not a readable zip file; it is truncated or corrupt.") from None
    files = check_entries(infos, name)
    objs = [i for i in files if i.filename.lower().endswith(".obj")]
    plys = [i for i in files if i.filename.lower().endswith(".ply")]
    caches = [i for i in files if i.filename.lower().endswith((".pc2", ".mdd", ".npy"))]
    meshes = objs or plys
    if not meshes:
        raise InputError(f"{name} contains no .obj or .ply files; zip numbered OBJ or PLY frames (frame_0001.obj, "
                         "...), or one mesh with its .pc2/.mdd/.npy cache.")
    if caches:
        if len(objs) + len(plys) != 1 or len(caches) != 1:
            raise InputError(f"{name} must hold one mesh (.obj/.ply) and one .pc2/.mdd/.npy cache, or only numbered "
                             f"frames; it has {len(objs) + len(plys)} meshes and {len(caches)} cache files.")
        if objs:
            return load_obj_cache(read(zf, objs[0], name), read(zf, caches[0], name), fps=fps, name=name)
        return animate(load_ply_static(read(zf, plys[0], name), name=name), read(zf, caches[0], name), fps=fps)
    if objs and plys:
        raise InputError(f"{name} mixes .obj and .ply frames; zip frames of one format.")
    meshes.sort(key=lambda i: natural_key(i.filename))
    first_name = meshes[0].filename
    if plys:
        rest, faces, vertex_colors = read_ply(read(zf, meshes[0], name), first_name)
        parts, part_ids = (Part("skin", DEFAULT_PART_COLORS["skin"]),), np.zeros(len(faces), np.int32)

        def vertices(info: zipfile.ZipInfo) -> np.ndarray:
            return read_ply(read(zf, info, name), info.filename)[0]
    else:
        rest, faces, group_of_face, groups = parse_obj(read(zf, meshes[0], name).decode("utf-8", errors="replace"),
                                                       first_name)
        parts, part_ids = parts_for_groups(groups, group_of_face, material_colors(zf, files, name))
        vertex_colors = None

        def vertices(info: zipfile.ZipInfo) -> np.ndarray:
            return parse_obj_vertices(read(zf, info, name).decode("utf-8", errors="replace"), info.filename)
    frames = np.empty((len(meshes), len(rest), 3), np.float32)
    frames[0] = rest
    for k, info in enumerate(meshes[1:], 1):
        v = vertices(info)
        if len(v) != len(rest):
            raise InputError(f"{info.filename} has {len(v)} vertices but {first_name} has {len(rest)}; every "
                             "frame must have the same topology.")
        frames[k] = v
    return FaceAnimation(frames, faces, part_ids, parts, float(fps or DEFAULT_FPS), name, vertex_colors=vertex_colors,
                         extras={"frame_files": [meshes[0].filename, meshes[-1].filename]})


def check_entries(infos: list[zipfile.ZipInfo], name: str) -> list[zipfile.ZipInfo]:
    """The regular file entries, after refusing unsafe zips."""
    if len(infos) > MAX_ENTRIES:
        raise InputError(f"{name} has {len(infos)} entries (more than {MAX_ENTRIES}); refusing it.")
    total = sum(i.file_size for i in infos)
    if total > MAX_TOTAL:
        raise InputError(f"{name} unpacks to {total} bytes (more than 2 GB); refusing it.")
    packed = sum(i.compress_size for i in infos)
    if total > RATIO_MIN_BYTES and total > MAX_RATIO * max(packed, 1):
        raise InputError(f"{name} is compressed more than {MAX_RATIO}:1, like a decompression bomb; refusing it.")
    files = []
    for i in infos:
        parts = re.split(r"[\\/]", i.filename)
        if i.filename.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", i.filename) or ".." in parts:
            raise InputError(f"{name}: entry {i.filename!r} has an absolute path or '..'; refusing the zip.")
        if stat.S_ISLNK(i.external_attr >> 16):
            raise InputError(f"{name}: entry {i.filename!r} is a symbolic link; refusing the zip.")
        if i.file_size > RATIO_MIN_BYTES and i.file_size > MAX_RATIO * max(i.compress_size, 1):
            raise InputError(f"{name}: entry {i.filename!r} is compressed more than {MAX_RATIO}:1, like a "
                             "decompression bomb; refusing the zip.")
        if i.flag_bits & 0x1:
            raise InputError(f"{name}: entry {i.filename!r} is encrypted; zip it without a password.")
        base = parts[-1]
        if i.is_dir() or parts[0] == "__MACOSX" or base.startswith("."):
            continue
        files.append(i)
    return files


def read(zf: zipfile.ZipFile, info: zipfile.ZipInfo, name: str) -> bytes:
    """One entry's bytes, never more than its declared size."""
    try:
        with zf.open(info) as fh:
            data = fh.read(info.file_size + 1)
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, NotImplementedError, RuntimeError) as exc:
        raise InputError(
            f"{name}: entry {info.filename!r} cannot be read ({str(exc)[:80]}); the zip is corrupt."
        ) from None
    if len(data) > info.file_size:
        raise InputError(f"{name}: entry {info.filename!r} is larger than its header says; the zip is corrupt.")
    return data


def natural_key(filename: str) -> list:
    """Sort key that orders frame2 before frame10."""
    return [(0, int(tok), "") if tok.isdigit() else (1, 0, tok.lower()) for tok in re.split(r"(\d+)", filename) if tok]


def material_colors(zf: zipfile.ZipFile, files: list[zipfile.ZipInfo], name: str) -> dict[str, tuple]:
    """Diffuse colours (Kd) of the materials in any .mtl of the zip."""
    colors: dict[str, tuple] = {}
    for info in files:
        if not info.filename.lower().endswith(".mtl"):
            continue
        current = None
        for line in read(zf, info, name).decode("utf-8", errors="replace").splitlines():
            tok = line.split()
            if len(tok) >= 2 and tok[0] == "newmtl":
                current = " ".join(tok[1:])
            elif len(tok) >= 4 and tok[0] == "Kd" and current is not None:
                try:
                    rgb = tuple(min(max(float(x), 0.0), 1.0) for x in tok[1:4])
                except ValueError:
                    continue
                if all(math.isfinite(c) for c in rgb):
                    colors[current] = rgb
    return colors
