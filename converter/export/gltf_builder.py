"""GltfBuilder: assemble a glTF 2.0 asset from numpy arrays, optionally meshopt-compressed (EXT_meshopt_compression).

Used by the GLB writer (converter/export/glb.py), samples/make_sample.py and the format tests; deterministic.
"""

from __future__ import annotations

import base64
import ctypes
import json
import struct

import numpy as np

COMPONENT_TYPES = {np.dtype(np.int8): 5120, np.dtype(np.uint8): 5121, np.dtype(np.int16): 5122,
                   np.dtype(np.uint16): 5123, np.dtype(np.uint32): 5125, np.dtype(np.float32): 5126}
TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def _pad4(n: int) -> int:
    return (n + 3) & ~3


class GltfBuilder:
    """Collects buffer views, accessors and JSON objects; writes .glb bytes or .gltf JSON + .bin."""

    def __init__(self, generator: str = "facesvg") -> None:
        self.doc: dict = {"asset": {"version": "2.0", "generator": generator}}
        self.bin = bytearray()
        self.fallback_bytes = 0  # size of the uncompressed twin buffer that meshopt views describe

    def add(self, kind: str, obj: dict) -> int:
        """Append a JSON object (node, mesh, material, ...) to its top-level array; returns its index."""
        items = self.doc.setdefault(kind, [])
        items.append(obj)
        return len(items) - 1

    def use_extension(self, name: str, required: bool = True) -> None:
        """Declare an extension as used (and required)."""
        for key in ("extensionsUsed",) + (("extensionsRequired",) if required else ()):
            names = self.doc.setdefault(key, [])
            if name not in names:
                names.append(name)

    def _append(self, raw: bytes) -> int:
        self.bin.extend(b"\0" * (_pad4(len(self.bin)) - len(self.bin)))
        off = len(self.bin)
        self.bin.extend(raw)
        return off

    def view(self, raw: bytes, stride: int | None = None, target: int | None = None, meshopt: str | None = None,
             count: int | None = None, filter: str | None = None) -> int:
        """A buffer view over raw bytes; meshopt='ATTRIBUTES'|'TRIANGLES'|'INDICES' stores it compressed."""
        if meshopt is None:
            bv: dict = {"buffer": 0, "byteOffset": self._append(raw), "byteLength": len(raw)}
        else:
            encoded = meshopt_encode(raw, meshopt, count, stride)
            self.use_extension("EXT_meshopt_compression")
            ext = {"buffer": 0, "byteOffset": self._append(encoded), "byteLength": len(encoded),
                   "byteStride": stride, "count": count, "mode": meshopt}
            if filter:
                ext["filter"] = filter
            bv = {"buffer": 1, "byteOffset": self.fallback_bytes, "byteLength": len(raw),
                  "extensions": {"EXT_meshopt_compression": ext}}
            self.fallback_bytes += _pad4(len(raw))
        if stride is not None and target == ARRAY_BUFFER:
            bv["byteStride"] = stride
        if target is not None:
            bv["target"] = target
        return self.add("bufferViews", bv)

    def accessor(self, array: np.ndarray, type_: str | None = None, normalized: bool = False, minmax: bool = False,
                 target: int | None = None, meshopt: str | None = None, filter: str | None = None) -> int:
        """An accessor over a (count, width) array; a 4-wide array with type_='VEC3' stores padded rows."""
        array = np.ascontiguousarray(array)
        if array.ndim == 1:
            array = array[:, None]
        count, width = array.shape
        type_ = type_ or TYPES[width]
        ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[type_]
        ctype = COMPONENT_TYPES[array.dtype]
        row = array.itemsize * width
        stride = row if (target == ARRAY_BUFFER or meshopt == "ATTRIBUTES") else None
        if meshopt in ("TRIANGLES", "INDICES"):
            stride = array.itemsize
        view = self.view(
            array.astype(array.dtype.newbyteorder("<")).tobytes(),
            stride=stride,
            target=target,
            meshopt=meshopt,
            count=count if meshopt != "TRIANGLES" and meshopt != "INDICES" else array.size,
            filter=filter,
        )
        acc: dict = {"bufferView": view, "componentType": ctype, "count": int(count if ncomp > 1 or width == 1
                                                                               else array.size), "type": type_}
        if normalized:
            acc["normalized"] = True
        if minmax:
            acc["min"] = [float(x) for x in array[:, :ncomp].min(0)]
            acc["max"] = [float(x) for x in array[:, :ncomp].max(0)]
        return self.add("accessors", acc)

    def sparse_accessor(self, count: int, indices: np.ndarray, values: np.ndarray, type_: str = "VEC3",
                        normalized: bool = False, minmax: bool = False) -> int:
        """An accessor of count zero rows (no bufferView) with the rows at indices replaced by values."""
        values = np.ascontiguousarray(values)
        indices = np.ascontiguousarray(indices)
        index_view = self.view(indices.astype(indices.dtype.newbyteorder("<")).tobytes())
        value_view = self.view(values.astype(values.dtype.newbyteorder("<")).tobytes())
        acc: dict = {"componentType": COMPONENT_TYPES[values.dtype], "count": int(count), "type": type_,
                     "sparse": {"count": int(len(indices)),
                                "indices": {"bufferView": index_view, "componentType": COMPONENT_TYPES[indices.dtype]},
                                "values": {"bufferView": value_view}}}
        if normalized:
            acc["normalized"] = True
        if minmax:  # over every row, the implicit zeros included
            acc["min"] = [float(x) for x in np.minimum(values.min(0), 0)]
            acc["max"] = [float(x) for x in np.maximum(values.max(0), 0)]
        return self.add("accessors", acc)

    def _finish(self, uri: str | None) -> dict:
        doc = json.loads(json.dumps(self.doc))
        buf: dict = {"byteLength": len(self.bin)}
        if uri is not None:
            buf["uri"] = uri
        doc["buffers"] = [buf]
        if self.fallback_bytes:
            doc["buffers"].append({"byteLength": self.fallback_bytes,
                                   "extensions": {"EXT_meshopt_compression": {"fallback": True}}})
        return doc

    def glb(self) -> bytes:
        """The asset as one binary .glb."""
        text = json.dumps(self._finish(None), separators=(",", ":")).encode()
        text += b" " * (_pad4(len(text)) - len(text))
        binary = bytes(self.bin) + b"\0" * (_pad4(len(self.bin)) - len(self.bin))
        total = 12 + 8 + len(text) + 8 + len(binary)
        return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
                + struct.pack("<II", len(binary), 0x004E4942) + binary)

    def gltf(self, bin_uri: str | None = None) -> tuple[bytes, bytes]:
        """(.gltf JSON, .bin bytes); with bin_uri=None the buffer is embedded as a base64 data: URI."""
        if bin_uri is None:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode()
            return json.dumps(self._finish(uri), indent=1).encode(), b""
        return json.dumps(self._finish(bin_uri), indent=1).encode(), bytes(self.bin)


def meshopt_encode(raw: bytes, mode: str, count: int | None, stride: int | None) -> bytes:
    """Compress one buffer view with meshoptimizer's encoders (format version 0, as EXT_meshopt_compression needs)."""
    import meshoptimizer as mo  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    if mode == "ATTRIBUTES":
        mo.encode_vertex_version(0)
        rows = np.frombuffer(raw, np.uint8).reshape(count, stride)
        return mo.encode_vertex_buffer(rows, count, stride)
    indices = np.frombuffer(raw, {2: "<u2", 4: "<u4"}[stride]).astype(np.uint32)
    mo.encode_index_version(1)
    vertex_count = int(indices.max()) + 1
    if mode == "TRIANGLES":
        return mo.encode_index_buffer(indices, len(indices), vertex_count)
    return mo.encode_index_sequence(indices, len(indices), vertex_count)


def _lib():
    from meshoptimizer._loader import lib  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    for fn in ("meshopt_encodeFilterOct", "meshopt_encodeFilterQuat"):
        getattr(lib, fn).argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_int, ctypes.c_void_p]
        getattr(lib, fn).restype = None
    lib.meshopt_encodeFilterExp.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_int,
                                            ctypes.c_void_p, ctypes.c_int]
    lib.meshopt_encodeFilterExp.restype = None
    return lib


def encode_filter(kind: str, data: np.ndarray, bits: int) -> np.ndarray:
    """meshoptimizer's filter encoders: quat (N,4)->int16; oct (N,4)->int8/int16 by bits; exp (N,C)->uint32."""
    data = np.ascontiguousarray(data, np.float32)
    n, width = data.shape
    lib = _lib()
    if kind == "quat":
        out = np.zeros((n, 4), np.int16)
        lib.meshopt_encodeFilterQuat(out.ctypes.data, n, 8, bits, data.ctypes.data)
    elif kind == "oct":
        out = np.zeros((n, 4), np.int8 if bits <= 8 else np.int16)
        lib.meshopt_encodeFilterOct(out.ctypes.data, n, out.itemsize * 4, bits, data.ctypes.data)
    else:
        out = np.zeros((n, width), np.uint32)
        lib.meshopt_encodeFilterExp(out.ctypes.data, n, 4 * width, bits, data.ctypes.data, 0)
    return out
