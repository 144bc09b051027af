"""glTF accessors: typed, strided, sparse and normalised data read from buffer views."""

from __future__ import annotations

import numpy as np

from converter.errors import InputError
from converter.formats.gltf.container import Container

MAX_ACCESSOR_COMPONENTS = 1 << 26  # numbers in one accessor (a 20M-vertex mesh); bounds what a tiny file can allocate
COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NORMALIZE_DIVISOR = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
INDEX_TYPES = (5121, 5123, 5125)


class Accessors(Container):
    """A glTF container that also decodes accessors."""

    def accessor(self, index: int, normalize: bool = True) -> np.ndarray:
        """Accessor data as (count, components) float64 (normalized integers mapped to [-1, 1] / [0, 1])."""
        acc = self.item("accessors", index)
        ctype = acc["componentType"]
        if ctype not in COMPONENT_DTYPES or acc.get("type") not in TYPE_COMPONENTS:
            raise InputError(f"{self.name}: accessor {index} has an unknown component type or type.")
        dtype = np.dtype(COMPONENT_DTYPES[ctype])
        nc = TYPE_COMPONENTS[acc["type"]]
        count = int(acc["count"])
        if count < 1 or count * nc > MAX_ACCESSOR_COMPONENTS:
            raise InputError(f"{self.name}: accessor {index} has an invalid count {count}.")
        if acc.get("bufferView") is not None:
            arr = self._strided(acc["bufferView"], int(acc.get("byteOffset", 0)), count, nc, dtype, index)
        else:
            arr = np.zeros((count, nc), dtype)
        sparse = acc.get("sparse")
        if sparse is not None:
            n = int(sparse["count"])
            if not 1 <= n <= count:
                raise InputError(f"{self.name}: sparse accessor {index} has an invalid count {n}.")
            ind, val = sparse["indices"], sparse["values"]
            if ind["componentType"] not in INDEX_TYPES:
                raise InputError(f"{self.name}: sparse accessor {index} has non-integer indices.")
            where = self._strided(ind["bufferView"], int(ind.get("byteOffset", 0)), n, 1,
                                  np.dtype(COMPONENT_DTYPES[ind["componentType"]]), index, packed=True)[:, 0]
            if where.max() >= count:
                raise InputError(f"{self.name}: sparse accessor {index} writes past its {count} elements.")
            arr = arr.copy()
            arr[where.astype(np.int64)] = self._strided(val["bufferView"], int(val.get("byteOffset", 0)), n, nc, dtype,
                                                        index, packed=True)
        if not normalize:
            return arr
        out = arr.astype(np.float64)
        if acc.get("normalized") and ctype in NORMALIZE_DIVISOR:
            out = np.maximum(out / NORMALIZE_DIVISOR[ctype], -1.0)
        return out

    def _strided(self, view_index: int, offset: int, count: int, nc: int, dtype: np.dtype, acc_index: int,
                 packed: bool = False) -> np.ndarray:
        """count rows of nc components from a buffer view, honouring its byteStride (unless packed)."""
        view = self.view(view_index)
        elem = dtype.itemsize * nc
        stride = elem if packed else int(self.item("bufferViews", view_index).get("byteStride") or elem)
        if offset < 0 or stride < elem or offset + stride * (count - 1) + elem > len(view):
            raise InputError(f"{self.name}: accessor {acc_index} reads past the end of its buffer view; the file is "
                             "truncated or corrupt.")
        return np.ndarray((count, nc), dtype, buffer=view, offset=offset, strides=(stride, dtype.itemsize)).copy()

    def indices(self, index: int) -> np.ndarray:
        """An index accessor as int64."""
        acc = self.item("accessors", index)
        if acc.get("componentType") not in INDEX_TYPES or acc.get("type") != "SCALAR":
            raise InputError(f"{self.name}: index accessor {index} is not unsigned integer scalars.")
        return self.accessor(index, normalize=False)[:, 0].astype(np.int64)

