"""Faces with named morph targets, for driving by weights: glTF targetNames, a zip of OBJ shapes, an ICT FaceKit folder.

A MorphFace is the rest mesh plus one delta per named target, in the scene's units. glTF targets are read by
posing the file through the glTF loader itself (one frame per target at weight 1), so node transforms, several
meshes sharing a target name, quantised or meshopt data all come out exactly as the loader draws them.

A VRM avatar's expressions (converter/formats/gltf/vrm.py) are targets too, beside the raw morphs: each is posed
as one frame with its binds' weights, so its delta is the sum of its binds' deltas times their weights (0.x weight
/ 100, 1.0 weight as is). It takes its VRM name (1.0 preset names, 0.x presets renamed to them, custom names);
where a raw morph already has that name, the expression shows as `vrm:<name>` (the weights stage still matches
it by the plain name, and prefers it: converter/blendshapes.py). Which targets are expressions, binary or
overriding, is in MorphFace.expressions; material binds move nothing and are reported in extras["warnings"].
"""

from __future__ import annotations

import base64
import gzip
import io
import json
import struct
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from converter.animation import FaceAnimation, Part
from converter.errors import InputError
from converter.formats import gltf
from converter.formats.gltf.names import target_names
from converter.formats.gltf.vrm import Expression, read_expressions
from converter.formats.ictfacekit import load_ict_head
from converter.formats.obj import parse_obj, parse_obj_vertices
from converter.formats.objseq import check_entries, material_colors, natural_key, read
from converter.formats.parts import parts_for_groups
from converter.options import Progress, no_progress
from converter.userfiles import read_bytes

NEUTRAL_NAMES = ("neutral", "base", "basis", "rest", "generic_neutral_mesh")
MAX_TARGETS = 1024
MAX_SHAPE_BYTES = 1 << 30  # one gunzipped shape OBJ


@dataclass(frozen=True)
class ExpressionTarget:
    """A VRM expression that is one of a MorphFace's targets: its index there, the expression (name, binds, isBinary,
    overrides) and the named raw targets its binds move."""

    index: int
    expression: Expression
    bound: tuple[int, ...]


@dataclass(frozen=True, eq=False)
class MorphFace:
    """A rest mesh and its named morph targets as deltas: base (V,3), deltas (K,V,3) float32, one name each."""

    base: np.ndarray
    deltas: np.ndarray
    names: list[str]
    faces: np.ndarray  # int32 (F, 3)
    part_ids: np.ndarray  # int32 (F,)
    parts: tuple[Part, ...]
    name: str = "face"
    vertex_colors: np.ndarray | None = None
    extras: dict = field(default_factory=dict)
    expressions: tuple[ExpressionTarget, ...] = ()  # VRM expressions among the targets (glTF faces only)

    def still(self, fps: float) -> FaceAnimation:
        """The rest mesh as a one-frame FaceAnimation (carries parts, colours and extras)."""
        return FaceAnimation(self.base[None], self.faces, self.part_ids, self.parts, fps, self.name,
                             vertex_colors=self.vertex_colors, extras=dict(self.extras))


def load_morph_face(path: str | Path, progress: Progress = no_progress) -> MorphFace:
    """A face with named morph targets from a glTF/GLB, a zip of OBJ shapes (neutral.obj + jawOpen.obj ...), or
    an ICT FaceKit folder; progress("load", fraction of its shapes read) after each shape of a zip or a folder
    (an ICT head's 27 are seconds of parsing; a glTF's come in one parse)."""
    path = Path(path)
    if path.is_dir():
        return from_ict(path, progress)
    data = read_bytes(path, "face")
    if not data:
        raise InputError(f"{path.name} is empty.")
    if data[:4] == b"glTF" or data.lstrip()[:1] == b"{":
        return from_gltf(data, path.parent, path.stem)
    if data[:4] in (b"PK\x03\x04", b"PK\x05\x06"):
        return from_obj_zip(data, path.stem, progress)
    raise InputError(f"{path.name} has no named morph targets to drive; give a glTF/GLB with targetNames, a zip of "
                     "OBJ shapes (neutral.obj, jawOpen.obj, ...) or an ICT FaceKit folder.")


def from_gltf(data: bytes, base_dir: Path, name: str = "face") -> MorphFace:
    """Named morph targets of every mesh (names as gltf.names reads them), then the VRM expressions, if any, as
    targets of their own (each the sum of its binds' targets times their weights), as world-space deltas of the
    rest pose."""
    doc, bin_chunk = gltf.parse_container(data, name)
    names: list[str] = []
    slots: list[tuple[int, list[str]]] = []  # (node index, target name per target slot)
    for i, node in enumerate(doc.get("nodes") or []):
        if not isinstance(node, dict) or not isinstance(node.get("mesh"), int):
            continue
        meshes = doc.get("meshes") or []
        mesh = (
            meshes[node["mesh"]] if 0 <= node["mesh"] < len(meshes) and isinstance(meshes[node["mesh"]], dict) else {}
        )
        prims = mesh.get("primitives") or [{}]
        k = len((prims[0] if isinstance(prims[0], dict) else {}).get("targets") or [])
        if not k:
            continue
        labels = target_names(mesh, k)
        slots.append((i, labels))
        names += [n for n in labels if n and n not in names]
    n_raw = len(names)
    found, notes = read_expressions(doc)
    animated = {node for node, _ in slots}
    if not names and not any(e.binds for e in found):
        raise InputError(f"{name} has no named morph targets (mesh.extras.targetNames) nor VRM expressions; export "
                         "the shape keys with their names (Blender: glTF export, Shape Keys on).")
    if len(names) + len(found) > MAX_TARGETS:
        raise InputError(f"{name} has {len(names) + len(found)} morph targets and expressions, more than "
                         f"{MAX_TARGETS}.")
    poses: list[dict[int, dict[int, float]]] = []  # per target: node -> {slot: weight}
    for label in names:
        poses.append({node: {s: 1.0 for s, n in enumerate(labels) if n == label} for node, labels in slots})
    labels_of = dict(slots)
    expressions = []
    for e in found:
        weights: dict[int, dict[int, float]] = {}
        for node, slot, w in e.binds:
            if node in animated:
                weights.setdefault(node, {})
                weights[node][slot] = weights[node].get(slot, 0.0) + w
        bound = sorted({names.index(labels_of[node][slot]) for node, slot, _ in e.binds
                        if node in animated and labels_of[node][slot]})
        shown = e.name if e.name not in names else f"vrm:{e.name}"  # a raw morph keeps its own name
        while shown in names:
            shown += "_"
        expressions.append(ExpressionTarget(len(names), e, tuple(bound)))
        names.append(shown)
        poses.append(weights)
    posed = _posing_document(doc, slots, poses)
    anim = gltf.load_gltf(_repack(posed, bin_chunk, data[:4] == b"glTF"), base_dir=base_dir, fps=1.0, name=name)
    if anim.n_frames != len(names) + 1:
        raise InputError(f"{name}: posing the morph targets gave {anim.n_frames} frames, expected {len(names) + 1}.")
    base = anim.frames[0]
    deltas = (anim.frames[1:] - base[None]).astype(np.float32)
    extras = {k: v for k, v in anim.extras.items() if k not in ("animation", "animated_nodes", "morph_animated_nodes")}
    if expressions:
        extras["morph_targets"] = names[:n_raw]
        extras["vrm_expressions"] = [x.expression.name for x in expressions]
    if notes:
        extras["warnings"] = [*extras.get("warnings", ()), *notes]
    return MorphFace(np.array(base), deltas, names, anim.faces, anim.part_ids, anim.parts, name,
                     anim.vertex_colors, extras, tuple(expressions))


def _posing_document(doc: dict, slots: list[tuple[int, list[str]]], poses: list[dict[int, dict[int, float]]]) -> dict:
    """A copy of doc whose only animation shows the rest pose at t=0 and pose j (node -> {target slot: weight})
    at t=j+1, over the morph targets of the slots' nodes."""
    n = len(poses) + 1
    blobs = [np.arange(n, dtype="<f4").tobytes()]
    samplers, channels = [], []
    for node, labels in slots:
        w = np.zeros((n, len(labels)), "<f4")
        for j, pose in enumerate(poses):
            for slot, value in pose.get(node, {}).items():
                w[j + 1, slot] = value
        blobs.append(w.tobytes())
    out = dict(doc)
    buffers = list(doc.get("buffers") or [])
    views = list(doc.get("bufferViews") or [])
    accessors = list(doc.get("accessors") or [])
    payload = b"".join(blobs)
    buffers.append({"byteLength": len(payload),
                    "uri": "data:application/octet-stream;base64," + base64.b64encode(payload).decode()})
    offset = 0
    acc_ids = []
    for k, blob in enumerate(blobs):
        views.append({"buffer": len(buffers) - 1, "byteOffset": offset, "byteLength": len(blob)})
        count = n if k == 0 else len(blob) // 4
        acc = {"bufferView": len(views) - 1, "componentType": 5126, "count": count, "type": "SCALAR"}
        if k == 0:
            acc.update({"min": [0.0], "max": [float(n - 1)]})
        accessors.append(acc)
        acc_ids.append(len(accessors) - 1)
        offset += len(blob)
    for k, (node, _) in enumerate(slots):
        samplers.append({"input": acc_ids[0], "output": acc_ids[k + 1], "interpolation": "STEP"})
        channels.append({"sampler": k, "target": {"node": node, "path": "weights"}})
    out.update(buffers=buffers, bufferViews=views, accessors=accessors,
               animations=[{"name": "morph targets", "samplers": samplers, "channels": channels}])
    return out


def _repack(doc: dict, bin_chunk, binary: bool) -> bytes:
    """The document as .gltf JSON bytes, or as a GLB carrying the original binary chunk."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    if not binary:
        return text
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if bin_chunk is not None:
        payload = bytes(bin_chunk)
        payload += b"\0" * (-len(payload) % 4)
        chunks += struct.pack("<II", len(payload), 0x004E4942) + payload
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def from_obj_zip(data: bytes, name: str = "face", progress: Progress = no_progress) -> MorphFace:
    """A zip of one neutral OBJ (neutral/base/basis.obj) and one OBJ per shape named for it (jawOpen.obj, ...).

    Shapes may be gzipped (.obj.gz) and must share the neutral's vertex order; each is an absolute mesh.
    progress("load", fraction of the shapes read) after each.
    """
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, OSError, KeyError, NotImplementedError):
        raise InputError(f"{name} is not a readable zip file; it is truncated or corrupt.") from None
    files = [i for i in check_entries(infos, name) if i.filename.lower().endswith((".obj", ".obj.gz"))]
    stems = {i.filename: _stem(i.filename) for i in files}
    neutral = [i for i in files if stems[i.filename].lower() in NEUTRAL_NAMES]
    if len(neutral) != 1:
        raise InputError(f"{name} must hold exactly one neutral OBJ (neutral.obj, base.obj or basis.obj) beside the "
                         f"shapes named for their targets (jawOpen.obj, ...); it has {len(neutral)}.")
    shapes = sorted((i for i in files if i is not neutral[0]), key=lambda i: natural_key(i.filename))
    if not shapes:
        raise InputError(f"{name} holds a neutral OBJ but no shapes; add one OBJ per target (jawOpen.obj, ...).")
    if len(shapes) > MAX_TARGETS:
        raise InputError(f"{name} has {len(shapes)} shapes, more than {MAX_TARGETS}.")
    base, faces, group_of_face, groups = parse_obj(_obj_text(zf, neutral[0], name), neutral[0].filename)
    deltas = np.empty((len(shapes), len(base), 3), np.float32)
    for k, info in enumerate(shapes):
        v = parse_obj_vertices(_obj_text(zf, info, name), info.filename)
        if v.shape != base.shape:
            raise InputError(f"{info.filename} has {len(v)} vertices but {neutral[0].filename} has {len(base)}; "
                             "every shape must keep the neutral's vertices in order.")
        deltas[k] = v - base
        progress("load", (k + 1) / len(shapes))
    parts, part_ids = parts_for_groups(groups, group_of_face, material_colors(zf, check_entries(infos, name), name))
    return MorphFace(base, deltas, [stems[i.filename] for i in shapes], faces, part_ids, parts, name)


def from_ict(folder: Path, progress: Progress = no_progress) -> MorphFace:
    """The ICT FaceKit head and all its expression shapes (deltas from the neutral); progress("load", fraction
    of the shapes read) after each."""
    head = load_ict_head(folder)
    names = head.expression_names()
    deltas = np.zeros((len(names), len(head.vertices), 3), np.float32)
    for k, n in enumerate(names):
        deltas[k] = head.delta(n)
        progress("load", (k + 1) / len(names))
    return MorphFace(head.vertices, deltas, names, head.faces, head.part_ids, head.parts, folder.name,
                     extras={"morph_targets": names})


def _stem(filename: str) -> str:
    base = filename.replace("\\", "/").rsplit("/", 1)[-1]
    for suffix in (".obj.gz", ".obj", ".OBJ"):
        if base.lower().endswith(suffix.lower()):
            return base[: -len(suffix)]
    return base


def _obj_text(zf: zipfile.ZipFile, info: zipfile.ZipInfo, name: str) -> str:
    raw = read(zf, info, name)
    if info.filename.lower().endswith(".gz"):
        try:
            with gzip.GzipFile(fileobj=io.BytesIO(raw)) as fh:
                raw = fh.read(MAX_SHAPE_BYTES + 1)
        except (OSError, EOFError, ValueError, zlib.error):
            raise InputError(f"{name}: {info.filename} is not a readable gzip file.") from None
        if len(raw) > MAX_SHAPE_BYTES:
            raise InputError(f"{name}: {info.filename} unpacks to more than 1 GB; refusing it.")
    return raw.decode("utf-8", errors="replace")
