"""Wavefront OBJ geometry: vertices and fan-triangulated faces with their material/group, vertex ids kept."""

from __future__ import annotations

import numpy as np

from converter.errors import InputError


def parse_obj(text: str, name: str = "OBJ") -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(vertices (V,3) float32, triangles (F,3) int32, group index per triangle (F,), group names).

    Faces are fan-triangulated; the group is the current `usemtl` (else `g`/`o`) name. Vertex ids are the
    file's own (UV seams do not split vertices), so point caches and expression shapes index them directly.
    """
    verts: list[list[float]] = []
    tris: list[tuple[int, int, int]] = []
    tri_group: list[int] = []
    groups: list[str] = []
    group_index: dict[str, int] = {}
    current = -1
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line[0] == "#":
            continue
        head, _, rest = line.partition(" ")
        if head == "v":
            parts = rest.split()
            if len(parts) < 3:
                raise InputError(f"{name} line {lineno}: a vertex needs x y z, got {line[:60]!r}.")
            try:
                verts.append([float(parts[0]), float(parts[1]), float(parts[2])])
            except ValueError:
                raise InputError(f"{name} line {lineno}: vertex coordinates are not numbers: {line[:60]!r}.") from None
        elif head == "f":
            try:
                idx = [int(tok.split("/", 1)[0]) for tok in rest.split()]
            except ValueError:
                raise InputError(f"{name} line {lineno}: face indices are not integers: {line[:60]!r}.") from None
            if len(idx) < 3:
                raise InputError(f"{name} line {lineno}: a face needs at least 3 vertices.")
            n = len(verts)
            idx = [i - 1 if i > 0 else n + i for i in idx]
            if current < 0:
                current = _group(groups, group_index, "default")
            for k in range(1, len(idx) - 1):
                tris.append((idx[0], idx[k], idx[k + 1]))
                tri_group.append(current)
        elif head in ("usemtl", "g", "o"):
            label = rest.strip() or "default"
            if head == "usemtl" or not any(g for g in groups if g != "default"):
                current = _group(groups, group_index, label)
    if not verts:
        raise InputError(f"{name} has no vertices.")
    if not tris:
        raise InputError(f"{name} has no faces.")
    v = np.asarray(verts, np.float32)
    f = np.asarray(tris, np.int64)
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{name}: a face refers to a vertex that does not exist.")
    return v, f.astype(np.int32), np.asarray(tri_group, np.int32), groups


def parse_obj_vertices(text: str, name: str = "OBJ") -> np.ndarray:
    """Only the vertex positions (V, 3) of an OBJ, fast: for expression shapes and frame sequences."""
    rows = [line[2:] for line in text.splitlines() if line.startswith("v ")]
    if not rows:
        raise InputError(f"{name} has no vertices.")
    try:
        arr = np.array([r.split()[:3] for r in rows], dtype=np.float32)
    except ValueError:
        raise InputError(f"{name}: vertex coordinates are not numbers.") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{name}: every vertex needs x y z.")
    return arr


def _group(groups: list[str], index: dict[str, int], label: str) -> int:
    if label not in index:
        index[label] = len(groups)
        groups.append(label)
    return index[label]
