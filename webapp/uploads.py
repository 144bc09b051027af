"""Checks on uploaded files before a job is queued: kind by content, zip safety, self-contained glTF."""

from __future__ import annotations

import json
import re
import stat
import zipfile
from pathlib import Path, PurePosixPath

from converter import formats
from converter.errors import InputError
from converter.options import option_fields

# Extra files a job may carry besides the main input: the point cache, and one per ConversionOptions path field.
EXTRA_FIELDS = ("cache", *(spec.name for spec in option_fields() if spec.meta.path))
SUFFIX = re.compile(r"^\.[a-z0-9]{1,8}$")
MAX_ZIP_ENTRIES = 20000
MAX_ZIP_RATIO = 200  # uncompressed / compressed per entry; beyond this a zip is treated as a bomb


def stored_name(field: str, original: str, kind: str | None = None) -> str:
    """A generated file name for an upload: the field name plus a safe suffix (the sniffed kind's if known)."""
    if kind:
        return f"{field}.{kind}"
    suffix = PurePosixPath((original or "").replace("\\", "/")).suffix.lower()
    return field + (suffix if SUFFIX.match(suffix) else ".bin")


def check_main_input(path: Path, max_unzipped: int) -> str:
    """The kind of the main input file ('glb', 'gltf', 'zip', 'obj') after the safety checks; else InputError."""
    with open(path, "rb") as fh:
        head = fh.read(8192)
    if not head:
        raise InputError("the uploaded file is empty; choose an animation file.")
    kind = formats.sniff(head)
    if kind == "zip":
        check_zip(path, max_unzipped)
    elif kind == "gltf":
        check_gltf_self_contained(path)
    return kind


def check_extra(path: Path, field: str, max_unzipped: int, shown: str = "") -> None:
    """Safety checks for an extra upload (zip archives are checked like the main input); shown: the user's name."""
    with open(path, "rb") as fh:
        head = fh.read(4)
    if not head:
        what = f"“{shown}”" if shown else "file"
        raise InputError(f"the uploaded {field.replace('_', ' ')} {what} is empty.")
    if head == b"PK\x03\x04":
        check_zip(path, max_unzipped)


def check_zip(path: Path, max_unzipped: int) -> None:
    """Refuse zips with absolute or '..' paths, symlinks, too many entries, or bomb-like sizes."""
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise InputError(f"the zip archive is damaged ({exc}); re-create it.") from None
    if len(infos) > MAX_ZIP_ENTRIES:
        raise InputError(f"the zip archive has {len(infos)} entries; the limit is {MAX_ZIP_ENTRIES}.")
    total = 0
    for info in infos:
        name = info.filename.replace("\\", "/")
        parts = PurePosixPath(name).parts
        if name.startswith("/") or re.match(r"^[A-Za-z]:", name) or ".." in parts:
            raise InputError(f"the zip archive contains an unsafe path {name!r}; use plain relative names.")
        if stat.S_ISLNK(info.external_attr >> 16):
            raise InputError(f"the zip archive contains a symbolic link {name!r}; store real files only.")
        total += info.file_size
        if info.file_size > MAX_ZIP_RATIO * max(info.compress_size, 1) and info.file_size > 1 << 20:
            raise InputError(f"the zip entry {name!r} expands {info.file_size // max(info.compress_size, 1)}x; "
                             "this looks like a zip bomb and is refused.")
    if total > max_unzipped:
        raise InputError(f"the zip archive expands to {total >> 20} MB; the limit is {max_unzipped >> 20} MB.")


def check_gltf_self_contained(path: Path) -> None:
    """A single uploaded .gltf may only use data: URIs (external files would be read from the server)."""
    try:
        doc = json.loads(path.read_bytes())
    except (ValueError, UnicodeDecodeError):
        raise InputError("the glTF file is not valid JSON; check the file.") from None
    if not isinstance(doc, dict):
        raise InputError("the glTF file is not a JSON object; check the file.")
    for key in ("buffers", "images"):
        for item in doc.get(key) or []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                raise InputError("this .gltf refers to external files; upload a .glb or a .gltf with embedded "
                                 "(data: URI) buffers instead.")
