"""Facial definition parameters: feature point -> vertex, parts (eyes, teeth, tongue), FAPU; JSON and Xface XML.

JSON layout (facesvg-fdp, version 1):
    {"format": "facesvg-fdp", "version": 1, "vertex_count": V,
     "points": {"2.1": 1234, ...},                        feature point "group.index" -> vertex id
     "positions": {"7.1": [x, y, z]},                     optional points given as positions
     "parts": {"left_eye": [[a, b], 17, ...], ...},       vertex ids; [a, b] is the half-open range a..b-1
     "fapu": {"ES0": 6.1, ...},                          optional override of the neutral distances
     "source": "how it was made"}
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from converter.errors import InputError
from converter.mpeg4.standard import FAPU_NAMES, FEATURE_POINTS
from converter.userfiles import read_bytes, write_atomic

FORMAT = "facesvg-fdp"
PART_NAMES = ("left_eye", "right_eye", "upper_teeth", "lower_teeth", "tongue")


@dataclass(eq=False)
class Fdp:
    """Feature points of one face mesh: vertex ids, extra positions, parts and FAPU neutral distances."""

    points: dict[str, int]
    parts: dict[str, list[int]] = field(default_factory=dict)
    fapu: dict[str, float] = field(default_factory=dict)
    positions: dict[str, list[float]] = field(default_factory=dict)
    vertex_count: int | None = None
    source: str = ""
    extra: dict = field(default_factory=dict)

    def point_positions(self, vertices: np.ndarray) -> dict[str, np.ndarray]:
        """Every feature point's 3D position on these vertices (vertex points, then explicit positions)."""
        out = {k: np.asarray(vertices[i], np.float64) for k, i in self.points.items()}
        out.update({k: np.asarray(p, np.float64) for k, p in self.positions.items() if k not in out})
        return out

    def check(self, n_vertices: int) -> None:
        """Raise InputError when a vertex id is outside the mesh or the FDP was made for another mesh."""
        if self.vertex_count is not None and self.vertex_count != n_vertices:
            raise InputError(
                f"the FDP was made for a mesh with {self.vertex_count} vertices, this one has {n_vertices}; "
                "run `facesvg fdp --auto` on this face."
            )
        for name, i in self.points.items():
            if not 0 <= i < n_vertices:
                raise InputError(f"FDP point {name} refers to vertex {i}, the mesh has {n_vertices}; fix the FDP file.")
        for name, ids in self.parts.items():
            if ids and (min(ids) < 0 or max(ids) >= n_vertices):
                raise InputError(
                    f"FDP part {name} refers to vertices outside the mesh ({n_vertices}); fix the FDP file."
                )


def _dist(a: np.ndarray, b: np.ndarray, axis: int | None) -> float:
    return float(abs(a[axis] - b[axis])) if axis is not None else float(np.linalg.norm(a - b))


def fapu_from_points(vertices: np.ndarray, points: dict[str, int] | dict[str, np.ndarray]) -> dict[str, float]:
    """The five FAPU neutral distances from feature points (vertex ids or positions); missing ones are left out.

    IRISD0 = |3.1 - 3.3| (else 3.2 - 3.4), ES0 = |3.5 - 3.6|, ENS0 = eyes-to-nose (3.5/3.6 mid to 9.15) height,
    MNS0 = 9.15 to 2.2 height, MW0 = |8.3 - 8.4| (else 2.4 - 2.5); distances are Euclidean except the two heights.
    """
    p = {k: (np.asarray(vertices[v], np.float64) if np.ndim(v) == 0 else np.asarray(v, np.float64))
         for k, v in points.items()}
    out: dict[str, float] = {}

    def first(*pairs):
        for a, b in pairs:
            if a in p and b in p:
                return p[a], p[b]
        return None

    if (pr := first(("3.1", "3.3"), ("3.2", "3.4"))) is not None:
        out["IRISD0"] = _dist(*pr, None)
    if (pr := first(("3.5", "3.6"))) is not None:
        out["ES0"] = _dist(*pr, None)
    if "9.15" in p and "3.5" in p and "3.6" in p:
        out["ENS0"] = _dist((p["3.5"] + p["3.6"]) / 2, p["9.15"], 1)
    if (pr := first(("9.15", "2.2"))) is not None:
        out["MNS0"] = _dist(*pr, 1)
    if (pr := first(("8.3", "8.4"), ("2.4", "2.5"))) is not None:
        out["MW0"] = _dist(*pr, None)
    return {k: v for k, v in out.items() if v > 0}


def _ids_to_json(ids: list[int]) -> list:
    """Compress sorted ids into [a, b) ranges where runs are long, single ints elsewhere."""
    a = np.unique(np.asarray(ids, np.int64))
    if a.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(a) != 1) + 1
    out: list = []
    for run in np.split(a, breaks):
        if run.size >= 3:
            out.append([int(run[0]), int(run[-1]) + 1])
        else:
            out.extend(int(x) for x in run)
    return out


def _ids_from_json(items, name: str) -> list[int]:
    ids: list[int] = []
    for it in items:
        if isinstance(it, int) and not isinstance(it, bool):
            ids.append(it)
        elif isinstance(it, list) and len(it) == 2 and all(isinstance(x, int) for x in it) and it[0] <= it[1]:
            ids.extend(range(it[0], it[1]))
        else:
            raise InputError(f"FDP part {name}: expected vertex ids or [start, end] ranges, got {str(it)[:30]}.")
    return ids


def fdp_to_json(fdp: Fdp) -> str:
    """Deterministic JSON text of an Fdp."""
    def key(k: str) -> tuple:
        return tuple(int(x) for x in k.split(".")) if all(x.isdigit() for x in k.split(".")) else (999, k)

    data = {
        "format": FORMAT,
        "version": 1,
        "source": fdp.source,
        "vertex_count": fdp.vertex_count,
        "fapu": {k: round(float(fdp.fapu[k]), 6) for k in FAPU_NAMES if k in fdp.fapu},
        "points": {k: int(fdp.points[k]) for k in sorted(fdp.points, key=key)},
        "positions": {k: [round(float(x), 6) for x in fdp.positions[k]] for k in sorted(fdp.positions, key=key)},
        "parts": {k: _ids_to_json(fdp.parts[k]) for k in sorted(fdp.parts)},
    }
    if not data["positions"]:
        del data["positions"]
    if fdp.extra:
        data["extra"] = fdp.extra
    text = json.dumps(data, indent=1, sort_keys=False)
    # one line per part keeps the file readable and small
    return text


def save_fdp(fdp: Fdp, path: str | Path) -> None:
    """Write the FDP as JSON (atomically)."""
    write_atomic(Path(path), fdp_to_json(fdp).encode())


def fdp_from_json(data: dict, name: str = "FDP") -> Fdp:
    """An Fdp from parsed JSON, validated."""
    if not isinstance(data, dict) or not isinstance(data.get("points"), dict):
        raise InputError(f"{name} is not an FDP file: expected a JSON object with \"points\".")
    points: dict[str, int] = {}
    for k, v in data["points"].items():
        if k not in FEATURE_POINTS:
            raise InputError(f"{name}: {k!r} is not an MPEG-4 feature point id (like '2.1').")
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise InputError(f"{name}: point {k} must be a vertex index (a non-negative integer), got {v!r}.")
        points[k] = v
    positions = {}
    for k, v in (data.get("positions") or {}).items():
        if k not in FEATURE_POINTS:
            raise InputError(f"{name}: {k!r} is not an MPEG-4 feature point id (like '7.1').")
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) for x in v)):
            raise InputError(f"{name}: position of {k} must be [x, y, z].")
        positions[k] = [float(x) for x in v]
    parts = {k: _ids_from_json(v if isinstance(v, list) else [v], k) for k, v in (data.get("parts") or {}).items()}
    fapu = {}
    for k, v in (data.get("fapu") or {}).items():
        if k not in FAPU_NAMES or not isinstance(v, (int, float)) or not v > 0:
            raise InputError(f"{name}: fapu entries must be {', '.join(FAPU_NAMES)} with positive values, "
                             f"got {k}={v!r}.")
        fapu[k] = float(v)
    vc = data.get("vertex_count")
    if vc is not None and (not isinstance(vc, int) or vc <= 0):
        raise InputError(f"{name}: vertex_count must be a positive integer.")
    return Fdp(points, parts, fapu, positions, vc, str(data.get("source", "")), dict(data.get("extra") or {}))


def parse_xface_fdp(text: str | bytes, name: str = "FDP") -> Fdp:
    """An Fdp from Xface's .fdp XML: FAPU, feature-point vertex indices (per submesh), eye pivots."""
    from lxml import etree  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    try:
        root = etree.fromstring(text.encode() if isinstance(text, str) else text,
                                etree.XMLParser(resolve_entities=False, no_network=True, recover=False))
    except etree.XMLSyntaxError as exc:
        raise InputError(f"{name} is not valid XML (line {exc.lineno}): {exc.msg}.") from None
    if root.tag != "xfdp":
        raise InputError(f"{name}: expected an Xface <xfdp> document, got <{root.tag}>.")
    fapu = {}
    el = root.find("head/fapu")
    if el is not None:
        for k in FAPU_NAMES:
            if k in el.attrib:
                try:
                    fapu[k] = float(el.attrib[k])
                except ValueError:
                    raise InputError(f"{name} line {el.sourceline}: FAPU {k} is not a number.") from None
    points: dict[str, int] = {}
    submesh: dict[str, list] = {}
    influences: dict[str, list] = {}
    for el in root.iter("fdp"):
        fp, idx = el.get("name"), el.get("index")
        if fp not in FEATURE_POINTS or idx is None or not idx.isdigit():
            raise InputError(f"{name} line {el.sourceline}: expected <fdp name=\"group.index\" index=\"vertex\">.")
        # A point may be listed once per submesh it moves (2.1 on the face and on the lower teeth); every
        # listing is kept, the vertex comes from the face submesh (below).
        submesh.setdefault(fp, []).append([el.get("affects", ""), int(idx)])
        influences.setdefault(fp, []).extend(
            [int(i.get("fap", 0)), i.get("type", ""), float(i.get("weight", 0))] for i in el.iter("influence"))
    # Xface numbers vertices per submesh; facesvg meshes are one vertex array, so only the face submesh's
    # (the one most points are on) vertex ids are usable as they are.
    names = [lst[0][0] for lst in submesh.values()]
    face_mesh = max(sorted(set(names)), key=names.count) if names else ""
    for fp, lst in submesh.items():
        for mesh, idx in lst:
            if mesh == face_mesh:
                points.setdefault(fp, idx)
    pivots, binds = {}, {}
    for b in root.iter("bind"):
        item, sm = b.get("item", ""), b.get("submesh", "")
        binds[item] = sm
        if b.get("pivotX") is not None:
            pivots[item] = [float(b.get(f"pivot{c}")) for c in "XYZ"]
    extra = {"xface": {"face_submesh": face_mesh, "submesh": submesh, "bind": binds, "pivots": pivots,
                       "influences": influences}}
    return Fdp(points, {}, fapu, {}, None, f"Xface FDP {name}", extra)


def load_fdp(path: str | Path, vertices: np.ndarray | None = None) -> Fdp:
    """Read an FDP (facesvg JSON or Xface XML, told apart by content); with vertices, validate and fill FAPU."""
    path = Path(path)
    raw = read_bytes(path, "FDP file", "; pass --fdp or run `facesvg fdp INPUT --auto`")
    head = raw.lstrip()[:1]
    if head == b"{":
        try:
            data = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{path.name} is not valid JSON: {getattr(exc, 'msg', exc)} "
                             f"(line {getattr(exc, 'lineno', '?')}).") from None
        fdp = fdp_from_json(data, path.name)
    elif head == b"<":
        fdp = parse_xface_fdp(raw, path.name)
    else:
        raise InputError(f"{path.name} is neither an FDP JSON file nor an Xface .fdp XML file.")
    if vertices is not None:
        fdp.check(len(vertices))
        computed = fapu_from_points(vertices, fdp.point_positions(vertices))
        fdp.fapu = {**computed, **fdp.fapu}
    return fdp
