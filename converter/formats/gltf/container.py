"""The glTF container: .glb chunks or .gltf JSON, buffers (binary chunk, data: URI, side file) and buffer views."""

from __future__ import annotations

import base64
import binascii
import json
import struct
from pathlib import Path
from urllib.parse import unquote

from converter.errors import InputError
from converter.formats.gltf.meshopt import decode_view

SUPPORTED_EXTENSIONS = {"KHR_mesh_quantization", "EXT_meshopt_compression"}
# Extensions that only change how textures or materials look: safe to ignore when we draw flat base colours.
IGNORABLE_EXTENSIONS = {
    "KHR_texture_transform", "KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif",
    "KHR_materials_variants", "KHR_lights_punctual", "EXT_lights_image_based",
}
IGNORABLE_PREFIXES = ("KHR_materials_",)


def parse_container(data: bytes, name: str = "glTF") -> tuple[dict, memoryview | None]:
    """(JSON document, binary chunk or None) of a .glb or a .gltf JSON text."""
    if not data:
        raise InputError(f"{name} is empty; give a .glb or .gltf file.")
    bin_chunk = None
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise InputError(f"{name} is truncated: the .glb header is incomplete.")
        _, version, length = struct.unpack_from("<4sII", data)
        if version != 2:
            raise InputError(f"{name} is glTF version {version}; only glTF 2.0 is supported, re-export as glTF 2.0.")
        if length > len(data):
            raise InputError(f"{name} is truncated: the header says {length} bytes, the file has {len(data)}.")
        view = memoryview(data)
        pos, json_chunk = 12, None
        while pos + 8 <= length:
            clen, ctype = struct.unpack_from("<II", data, pos)
            pos += 8
            if pos + clen > length:
                raise InputError(f"{name} is truncated: a chunk runs past the end of the file.")
            if ctype == 0x4E4F534A and json_chunk is None:
                json_chunk = bytes(view[pos:pos + clen])
            elif ctype == 0x004E4942 and bin_chunk is None:
                bin_chunk = view[pos:pos + clen]
            pos += clen
        if json_chunk is None:
            raise InputError(f"{name} has no JSON chunk; the .glb is corrupt.")
        text = json_chunk
    else:
        text = data
    try:
        doc = json.loads(bytes(text).decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise InputError(f"{name}: the glTF JSON is garbled; re-export the file.") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise InputError(f"{name} is not a glTF document (no 'asset'); re-export it as glTF 2.0.")
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2"):
        raise InputError(f"{name} is glTF version {version or '?'}; only glTF 2.0 is supported.")
    return doc, bin_chunk


class Container:
    """One parsed glTF with lazily loaded, cached buffers and buffer views."""

    def __init__(self, doc: dict, bin_chunk: memoryview | None, base_dir: Path, name: str) -> None:
        self.doc, self.bin, self.base_dir, self.name = doc, bin_chunk, base_dir, name
        self._buffers: dict[int, memoryview] = {}
        self._views: dict[int, memoryview] = {}
        required = doc.get("extensionsRequired") or []
        unsupported = [e for e in required if e not in SUPPORTED_EXTENSIONS and e not in IGNORABLE_EXTENSIONS
                       and not str(e).startswith(IGNORABLE_PREFIXES)]
        if unsupported:
            raise InputError(f"{name} requires the glTF extension {', '.join(map(str, unsupported))}, which facesvg "
                             "does not support; re-export without it (e.g. with gltfpack, or uncompressed).")

    def item(self, kind: str, index) -> dict:
        """The JSON object kind[index] (e.g. "nodes", 3), or InputError when it does not exist."""
        items = self.doc.get(kind) or []
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise InputError(f"{self.name}: {kind[:-1]} {index!r} does not exist; the glTF is corrupt.")
        item = items[index]
        if not isinstance(item, dict):
            raise InputError(f"{self.name}: {kind[:-1]} {index} is not an object; the glTF is corrupt.")
        return item

    def buffer(self, index: int) -> memoryview:
        """The bytes of buffer index: the .glb binary chunk, a data: URI, or a file next to the glTF."""
        if index in self._buffers:
            return self._buffers[index]
        buf = self.item("buffers", index)
        uri = buf.get("uri")
        if uri is None:
            if index != 0 or self.bin is None:
                raise InputError(f"{self.name}: buffer {index} has no data (no uri and no .glb binary chunk).")
            data = self.bin
        elif uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                raise InputError(f"{self.name}: buffer {index} has a data: URI that is not base64.")
            try:
                data = memoryview(base64.b64decode(payload, validate=True))
            except (binascii.Error, ValueError):
                raise InputError(f"{self.name}: buffer {index} has a garbled base64 data: URI.") from None
        else:
            data = memoryview(self._external(uri, index))
        if len(data) < int(buf.get("byteLength", 0)):
            raise InputError(f"{self.name}: buffer {index} is truncated ({len(data)} of {buf['byteLength']} bytes).")
        self._buffers[index] = data
        return data

    def _external(self, uri: str, index: int, kind: str = "buffer") -> bytes:
        """An external buffer (or image) file, refused when its path leaves base_dir."""
        rel = unquote(uri)
        if "://" in rel or rel.startswith(("/", "\\")) or (len(rel) > 1 and rel[1] == ":"):
            raise InputError(f"{self.name}: {kind} {index} points to {uri!r}; only files next to the glTF are read.")
        root = self.base_dir.resolve()
        path = (root / rel).resolve()
        if not path.is_relative_to(root):
            raise InputError(f"{self.name}: {kind} {index} points outside the glTF's folder ({uri!r}); refusing it.")
        try:
            return path.read_bytes()
        except OSError:
            raise InputError(f"{self.name}: external {kind} {uri!r} is missing; put it next to the .gltf.") from None

    def view(self, index: int) -> memoryview:
        """The bytes of buffer view index, meshopt-decoded when compressed."""
        if index in self._views:
            return self._views[index]
        bv = self.item("bufferViews", index)
        ext = (bv.get("extensions") or {}).get("EXT_meshopt_compression")
        if ext is not None:
            data = decode_view(ext, self.buffer(ext["buffer"]), self.name, index)
        else:
            buf = self.buffer(bv["buffer"])
            off, length = int(bv.get("byteOffset", 0)), int(bv["byteLength"])
            if off < 0 or length < 0 or off + length > len(buf):
                raise InputError(f"{self.name}: buffer view {index} runs past the end of its buffer; "
                                 "the file is truncated.")
            data = buf[off:off + length]
        self._views[index] = data
        return data

