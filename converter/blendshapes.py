"""Driving a face's named morph targets with a weight capture (ARKit blendshapes): FACE + WeightTrack -> FaceAnimation.

Frames are base + (weights @ mapping) @ deltas, computed in blocks of frames so a long capture on a dense face
only ever holds one block of intermediates beside the output. Names match after normalisation (case, separators,
`Left/Right` = `_L/_R` = `.L/.R`, namespace and `ARKit_`/`blendShape.` prefixes); a capture weight without a side
(ARKit's `browInnerUp`, `cheekPuff`) drives both sides of a face that splits it (ICT's `browInnerUp_L/_R`).

Head yaw/pitch/roll turn the whole face rigidly about the centre of its rest bounding box (where ARKit's face
anchor sits: the middle of the head); eye yaw/pitch/roll turn the face's eye parts (eye/iris) about each
eyeball's fitted centre. Axes: yaw about +y (up), pitch about +x (the face's left), roll about +z (forward),
applied as R = Ry(yaw) Rx(pitch) Rz(roll).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.morphs import MorphFace, load_morph_face
from converter.formats.weights import WeightTrack, read_weights
from converter.mpeg4.tables import sphere_center
from converter.options import Progress, no_progress, span

BLOCK_FLOATS = 1 << 24  # floats per block of frames (64 MB of float32 intermediates)
MAX_OUTPUT_FLOATS = 1 << 30  # 4 GB of float32 frames: refuse captures that would not fit
EYE_PARTS = ("eye", "iris")
_SIDE = re.compile(r"(?:[._\s-](l|r|left|right)|(left|right))$", re.I)
_PREFIX = re.compile(r"^(?:arkit|bs|blendshapes?|shapes?|morphs?)[_\-\s]+", re.I)
FACE_READ_SHARE = 0.5  # of drive_file's progress, reading the face (an ICT head: 3 s; driving it by 1,000 frames
# 0.6 s, by 4,000 2.4 s)


def normalise(name: str) -> tuple[str, str]:
    """(base, side) of a blendshape name: 'eyeBlink_L', 'blendShape1.eyeBlink.L' -> ('eyeblink', 'L')."""
    s = name.strip()
    side = ""
    m = _SIDE.search(s)
    if m and m.start() > 0:
        side = (m.group(1) or m.group(2))[0].upper()
        s = s[: m.start()]
    s = re.split(r"[.:|]", s)[-1] if re.search(r"[.:|]", s) else s  # namespaces: blendShape1.jawOpen, ARKit:jawOpen
    s = _PREFIX.sub("", s)
    return re.sub(r"[\s_\-.]", "", s).lower(), side


@dataclass(frozen=True)
class Match:
    """How capture weights map onto targets: mapping (K_weights, K_targets) and the names left over."""

    mapping: np.ndarray  # float32 (Kw, Kt), 1 where weight i drives target j
    unmatched_weights: list[str]
    undriven_targets: list[str]
    duplicates: list[str]  # capture names that normalise like an earlier one (ignored)


def match_names(weights: list[str], targets: list[str]) -> Match:
    """Pair capture weight names with target names by normalised name (see the module docstring)."""
    index: dict[tuple[str, str], list[int]] = {}
    for j, t in enumerate(targets):
        index.setdefault(normalise(t), []).append(j)
    mapping = np.zeros((len(weights), len(targets)), np.float32)
    seen: set[tuple[str, str]] = set()
    unmatched, duplicates = [], []
    for i, w in enumerate(weights):
        key = normalise(w)
        if key in seen:
            duplicates.append(w)
            continue
        seen.add(key)
        hits = index.get(key)
        if not hits and not key[1]:
            hits = index.get((key[0], "L"), []) + index.get((key[0], "R"), [])
        if hits:
            mapping[i, hits] = 1.0
        else:
            unmatched.append(w)
    undriven = [t for j, t in enumerate(targets) if not mapping[:, j].any()]
    return Match(mapping, unmatched, undriven, duplicates)


def rotations(ypr: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotation matrices Ry(yaw) Rx(pitch) Rz(roll) from (T, 3) radians."""
    y, p, r = (ypr[:, k].astype(np.float64) for k in range(3))
    cy, sy, cp, sp, cr, sr = np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    one, zero = np.ones_like(y), np.zeros_like(y)
    ry = np.stack([np.stack([cy, zero, sy], -1), np.stack([zero, one, zero], -1), np.stack([-sy, zero, cy], -1)], 1)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cp, -sp], -1), np.stack([zero, sp, cp], -1)], 1)
    rz = np.stack([np.stack([cr, -sr, zero], -1), np.stack([sr, cr, zero], -1), np.stack([zero, zero, one], -1)], 1)
    return ry @ rx @ rz


def eye_vertices(face: MorphFace) -> tuple[np.ndarray, np.ndarray] | None:
    """Vertex ids of the face's left (+x) and right eye parts, or None when it has no eyes on both sides."""
    eye_ids = [k for k, p in enumerate(face.parts) if p.name in EYE_PARTS]
    if not eye_ids:
        return None
    verts = np.unique(face.faces[np.isin(face.part_ids, eye_ids)])
    x = face.base[verts, 0]
    mid = 0.5 * (float(x.min()) + float(x.max()))
    left, right = verts[x > mid], verts[x <= mid]
    if len(left) < 4 or len(right) < 4:
        return None
    return left, right


def drive(face: MorphFace, track: WeightTrack, fps: float | None = None,
          progress: Progress = no_progress) -> FaceAnimation:
    """The face animated by the track (resampled to fps when given); extras["weights"] says what matched and applied."""
    if fps is not None and abs(fps - track.fps) > 1e-9:
        track = track.sampled(fps)
    t, v = track.n_frames, len(face.base)
    if t * v * 3 > MAX_OUTPUT_FLOATS:
        raise InputError(f"{track.n_frames} frames x {v} vertices is too much to convert; lower --fps or trim the "
                         "capture.")
    m = match_names(track.names, face.names)
    driven = np.flatnonzero(m.mapping.any(axis=0))
    if not len(driven):
        raise InputError(f"none of the {len(track.names)} capture weights ({', '.join(track.names[:3])}, ...) names a "
                         f"morph target of the face ({', '.join(face.names[:3])}, ...); rename the targets to ARKit "
                         "names.")
    target_w = track.values @ m.mapping[:, driven]  # (T, Kd)
    deltas = face.deltas[driven].reshape(len(driven), -1)  # (Kd, V*3)
    head = track.head if track.head is not None and np.abs(track.head).max() > 0 else None
    eyes = eye_vertices(face)
    eye_tracks = (track.eye_left, track.eye_right)
    has_eye_angles = any(e is not None and np.abs(e).max() > 0 for e in eye_tracks)
    apply_eyes = eyes is not None and has_eye_angles
    lo, hi = face.base.min(0), face.base.max(0)
    pivot = (0.5 * (lo + hi)).astype(np.float32)
    centres = [sphere_center(face.base[ids]).astype(np.float32) for ids in eyes] if apply_eyes else []

    frames = np.empty((t, v, 3), np.float32)
    block = max(1, BLOCK_FLOATS // max(1, v * 3))
    base = face.base.reshape(-1).astype(np.float32)
    pivots = np.tile(pivot, v)  # (3V,): the head's pivot at every vertex, matching the frames' rows
    for s in range(0, t, block):
        e = min(t, s + block)
        out = frames[s:e].reshape(e - s, -1)
        np.matmul(target_w[s:e], deltas, out=out)
        out += base
        pts = frames[s:e]
        if apply_eyes:
            for ids, centre, ang in zip(eyes, centres, eye_tracks):
                if ang is None:
                    continue
                r = rotations(ang[s:e]).astype(np.float32)
                pts[:, ids] = (pts[:, ids] - centre) @ np.swapaxes(r, 1, 2) + centre
        if head is not None:
            r = rotations(head[s:e]).astype(np.float32)
            # batched matmul: 5x faster than the equivalent einsum for (B, V, 3) x (B, 3, 3). The pivot is taken
            # off and put back as a row of V pivots over (B, 3V): numpy broadcasting a last axis of 3 ran its
            # inner loop 3 elements at a time (3x the matmul's time); the same subtractions and additions.
            centred = (out - pivots).reshape(pts.shape)
            turned = (centred @ np.swapaxes(r, 1, 2)).reshape(out.shape)
            np.add(turned, pivots, out=out)
        progress("weights", e / t)
    weights_info = {
        "weights_matched": len(track.names) - len(m.unmatched_weights) - len(m.duplicates),
        "weights_unmatched": len(m.unmatched_weights),
        "targets_driven": len(driven),
        "targets_undriven": len(m.undriven_targets),
        "head_rotation_applied": int(head is not None),
        "eye_rotation_applied": int(apply_eyes),
    }
    warnings = []
    if m.unmatched_weights:
        warnings.append(f"{len(m.unmatched_weights)} capture weights found no morph target: "
                        f"{', '.join(m.unmatched_weights)}.")
    if m.undriven_targets:
        warnings.append(f"{len(m.undriven_targets)} morph targets got no weight: {', '.join(m.undriven_targets)}.")
    if m.duplicates:
        warnings.append(f"capture weights named like earlier ones were ignored: {', '.join(m.duplicates)}.")
    if has_eye_angles and not apply_eyes:
        warnings.append("the capture's eye rotations were not applied: the face has no eye parts on both sides.")
    extras = {**face.extras, "weights": {"counts": weights_info, "warnings": warnings, "source": track.source,
                                         "start_timecode": track.start_timecode}}
    return FaceAnimation(frames, face.faces, face.part_ids, face.parts, float(track.fps), face.name,
                         vertex_colors=face.vertex_colors, extras=extras)


def drive_file(face_path: str | Path, weights_path: str | Path, fps: float | None = None,
               progress: Progress = no_progress) -> FaceAnimation:
    """Read a face with named morph targets and a weight capture, and drive the one with the other; progress
    through both, reading the face's shapes up to FACE_READ_SHARE."""
    face = load_morph_face(face_path, span(progress, 0.0, FACE_READ_SHARE))
    anim = drive(face, read_weights(weights_path), fps=fps, progress=span(progress, FACE_READ_SHARE, 1.0))
    anim.extras.setdefault("source_path", str(face_path))
    return anim
