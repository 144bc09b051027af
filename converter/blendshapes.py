"""Driving a face's named morph targets with a weight capture (ARKit blendshapes): FACE + WeightTrack -> FaceAnimation.

Frames are base + (weights @ mapping) @ deltas, computed in blocks of frames so a long capture on a dense face
only ever holds one block of intermediates beside the output. Names match after normalisation (case, separators,
`Left/Right` = `_L/_R` = `.L/.R`, namespace and `ARKit_`/`blendShape.` prefixes); a capture weight without a side
(ARKit's `browInnerUp`, `cheekPuff`) drives both sides of a face that splits it (ICT's `browInnerUp_L/_R`).

Head yaw/pitch/roll turn the whole face rigidly about the centre of its rest bounding box (where ARKit's face
anchor sits: the middle of the head); eye yaw/pitch/roll turn the face's eye parts (eye/iris) about each
eyeball's fitted centre. Axes: yaw about +y (up), pitch about +x (the face's left), roll about +z (forward),
applied as R = Ry(yaw) Rx(pitch) Rz(roll).

VRM avatars (`match_face`): their expressions are targets of the face (converter/formats/morphs.py). By name, an
expression wins over a raw morph of the same name (VRM's "perfect sync" avatars carry the 52 ARKit names as
expressions over like-named morphs: the expressions are the avatar's own tuning). A face with VRM presets that names
few of a capture's ARKit weights (a plain VRoid avatar) is driven through ARKIT_TO_VRM instead, the mapping
carrying the table's weights; capture weights outside the table still drive targets of their names. An
expression's weight is clamped to 0..1, an isBinary one is 1 above 0.5 and 0 otherwise, and VRM 1.0's
overrideBlink/LookAt/Mouth (block, blend) then act on the procedural presets as the VRM 1.0 specification says
(expressions.md, "Procedural override", and its isBinary interaction). extras["weights"]["route"] says which way
the capture went: "names" or "vrm-table".
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.gltf.vrm import PROCEDURAL
from converter.formats.morphs import ExpressionTarget, MorphFace, load_morph_face
from converter.formats.weights import WeightTrack, read_weights
from converter.mpeg4.tables import sphere_center
from converter.options import Progress, no_progress, span

BLOCK_FLOATS = 1 << 24  # floats per block of frames (64 MB of float32 intermediates)
MAX_OUTPUT_FLOATS = 1 << 30  # 4 GB of float32 frames: refuse captures that would not fit
EYE_PARTS = ("eye", "iris")
_SIDE = re.compile(r"(?:[._\s-](l|r|left|right)|(left|right))$", re.I)
_PREFIX = re.compile(r"^(?:arkit|bs|blendshapes?|shapes?|morphs?)[_\-\s]+", re.I)
FACE_READ_SHARE = 0.5  # of drive_file's progress, reading the face (an ICT head takes about as long to read as to
# drive by a long capture: bench_weights)

# ARKit blendshape -> (VRM preset, weight) for avatars with VRM expressions but few ARKit-named targets. Our own
# table, not a published one: each pairing follows Apple's description of the blendshape
# (ARFaceAnchor.BlendShapeLocation) and the VRM 1.0 spec's meaning of the preset (expressions.md: aa/ih/ou/ee/oh are
# the vowels a, i, u, e, o; blink*/look* the eyelids and gaze; happy, angry, sad, surprised). A pair of sided
# weights (Left, Right) each give half, so both at 1 make the preset 1. Sides are the face's own, as in both specs.
# Gaze: ARKit's eyeLookOutLeft and eyeLookInRight both turn the eyes to the face's left (lookLeft). relaxed has no
# ARKit counterpart and is left undriven.
ARKIT_TO_VRM: dict[str, tuple[tuple[str, float], ...]] = {
    "jawOpen": (("aa", 1.0),),
    "mouthFunnel": (("oh", 1.0),),  # lips rounded and open: o
    "mouthPucker": (("ou", 1.0),),  # lips rounded and pushed out: u
    "mouthStretchLeft": (("ih", 0.5),), "mouthStretchRight": (("ih", 0.5),),  # corners pulled wide: i
    "mouthLowerDownLeft": (("ee", 0.5),), "mouthLowerDownRight": (("ee", 0.5),),  # lower lip down, teeth shown: e
    "mouthSmileLeft": (("happy", 0.5),), "mouthSmileRight": (("happy", 0.5),),
    "mouthFrownLeft": (("sad", 0.5),), "mouthFrownRight": (("sad", 0.5),),
    "browDownLeft": (("angry", 0.5),), "browDownRight": (("angry", 0.5),),
    "eyeWideLeft": (("surprised", 0.5),), "eyeWideRight": (("surprised", 0.5),),
    "eyeBlinkLeft": (("blinkLeft", 1.0),), "eyeBlinkRight": (("blinkRight", 1.0),),
    "eyeLookUpLeft": (("lookUp", 0.5),), "eyeLookUpRight": (("lookUp", 0.5),),
    "eyeLookDownLeft": (("lookDown", 0.5),), "eyeLookDownRight": (("lookDown", 0.5),),
    "eyeLookOutLeft": (("lookLeft", 0.5),), "eyeLookInRight": (("lookLeft", 0.5),),
    "eyeLookInLeft": (("lookRight", 0.5),), "eyeLookOutRight": (("lookRight", 0.5),),
}
# A preset the face lacks passes its weight to another, times a factor: a one-sided blink to both eyes' blink.
VRM_FALLBACK = {"blinkLeft": ("blink", 0.5), "blinkRight": ("blink", 0.5)}
TABLE_ROUTE_NAMED = 0.5  # the table drives a VRM face when fewer than this share of the capture's table weights
# find a target by name (a perfect-sync avatar names them all; a plain VRoid one none)


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
    route: str = "names"  # "names", or "vrm-table" when ARKIT_TO_VRM drove a VRM face's presets
    notes: tuple[str, ...] = ()  # for the report's warnings
    expressions: tuple[ExpressionTarget, ...] = ()  # the face's VRM expressions, whose rules weights() applies

    def weights(self, values: np.ndarray, driven: np.ndarray) -> np.ndarray:
        """(T, len(driven)) weights of the driven targets: values @ mapping, then the VRM expressions' rules."""
        w = values @ self.mapping[:, driven]
        column = {int(j): c for c, j in enumerate(driven)}
        exprs = [(column[x.index], x.expression) for x in self.expressions if x.index in column]
        for c, e in exprs:
            v = np.clip(w[:, c], 0.0, 1.0)
            w[:, c] = (v > 0.5) if e.binary else v
        for kind, procedural in PROCEDURAL.items():
            amount = np.zeros(len(w), w.dtype)
            for c, e in exprs:
                mode = dict(e.overrides).get(kind)
                if mode == "block":
                    amount += w[:, c] > 0
                elif mode == "blend":
                    amount += w[:, c]
            if not amount.any():
                continue
            factor = np.maximum(0.0, 1.0 - amount)
            for c, e in exprs:
                if e.preset and e.name in procedural:
                    w[:, c] = np.where(amount > 0, 0.0, w[:, c]) if e.binary else w[:, c] * factor
        return w


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


def match_face(weights: list[str], face: MorphFace) -> Match:
    """Match capture weight names onto a face: by name (a VRM expression before a raw morph of its name), or through
    ARKIT_TO_VRM for a VRM face that names few of the capture's table weights (see the module docstring)."""
    m = match_names(weights, face.names)
    if not face.expressions:
        return m
    mapping = m.mapping.copy()
    is_expression = np.zeros(len(face.names), bool)
    is_expression[[x.index for x in face.expressions]] = True
    for i in np.flatnonzero((mapping[:, is_expression] > 0).any(axis=1)):
        mapping[i, ~is_expression] = 0.0  # the expression, not the raw morph of the same name
    table = {normalise(k): v for k, v in ARKIT_TO_VRM.items()}
    presets = {x.expression.name: x.index for x in face.expressions if x.expression.preset}
    rows, seen, repeated = {}, set(), set()
    for i, w in enumerate(weights):
        key = normalise(w)
        if key in seen:
            repeated.add(i)
        elif key in table:
            rows[i] = table[key]
        seen.add(key)
    named = sum(1 for i in rows if mapping[i].any())
    route, notes = "names", []
    if rows and presets and named < TABLE_ROUTE_NAMED * len(rows):
        route = "vrm-table"
        notes.append(f"the face has VRM expressions but names {named} of the capture's {len(rows)} ARKit weights "
                     "that map to VRM presets: they drive its presets through facesvg's ARKit-to-VRM table "
                     "(converter.blendshapes.ARKIT_TO_VRM).")
        for i, pairs in rows.items():
            row = np.zeros(len(face.names), np.float32)
            for preset, factor in pairs:
                if preset not in presets and preset in VRM_FALLBACK:
                    preset, scale = VRM_FALLBACK[preset]
                    factor *= scale
                if preset in presets:
                    row[presets[preset]] += factor
            if row.any():  # else the weight keeps any target of its own name
                mapping[i] = row
    driven = mapping.any(axis=0)
    moved = {j for x in face.expressions for j in x.bound}  # raw morphs an expression moves: reported through it
    binary = [face.names[x.index] for x in face.expressions if x.expression.binary and driven[x.index]]
    if binary:
        notes.append(f"VRM expressions {', '.join(binary)} are binary (isBinary): on above a weight of 0.5, else off.")
    matched = mapping.any(axis=1)
    unmatched = [w for i, w in enumerate(weights) if not matched[i] and i not in repeated]
    undriven = [t for j, t in enumerate(face.names) if not driven[j] and j not in moved]
    return Match(mapping, unmatched, undriven, m.duplicates, route, tuple(notes), face.expressions)


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
    """The face animated by the track (resampled to fps when given); extras["weights"] says what matched and applied.

    Frame k of the animation is at k / fps: a track whose rows are off that grid (dropped rows, a recorder's
    clock drifting) is resampled onto it at its own rate, so the animation lasts as long as the take."""
    rate = track.fps if fps is None else fps
    # Rows within half a frame of their grid slot are kept as they are: that is what nearest-row resampling
    # would pick, and linear resampling would only blur them.
    if abs(rate - track.fps) > 1e-9 or not track.is_regular(tol=0.5):
        track = track.sampled(rate)
    t, v = track.n_frames, len(face.base)
    if t * v * 3 > MAX_OUTPUT_FLOATS:
        raise InputError(f"{track.n_frames} frames x {v} vertices is too much to convert; lower --fps or trim the "
                         "capture.")
    m = match_face(track.names, face)
    driven = np.flatnonzero(m.mapping.any(axis=0))
    if not len(driven):
        raise InputError(f"none of the {len(track.names)} capture weights ({', '.join(track.names[:3])}, ...) names a "
                         f"morph target of the face ({', '.join(face.names[:3])}, ...); rename the targets to ARKit "
                         "names.")
    target_w = m.weights(track.values, driven)  # (T, Kd)
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
            # batched matmul: faster than the equivalent einsum for (B, V, 3) x (B, 3, 3). The pivot is taken
            # off and put back as a row of V pivots over (B, 3V): numpy broadcasting a last axis of 3 ran its
            # inner loop 3 elements at a time (slower than the matmul); the same subtractions and additions.
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
    warnings = list(m.notes)
    if m.unmatched_weights:
        warnings.append(f"{len(m.unmatched_weights)} capture weights found no morph target: "
                        f"{', '.join(m.unmatched_weights)}.")
    if m.undriven_targets:
        warnings.append(f"{len(m.undriven_targets)} morph targets got no weight: {', '.join(m.undriven_targets)}.")
    if m.duplicates:
        warnings.append(f"capture weights named like earlier ones were ignored: {', '.join(m.duplicates)}.")
    if has_eye_angles and not apply_eyes:
        warnings.append("the capture's eye rotations were not applied: the face has no eye parts on both sides.")
    extras = {**face.extras, "weights": {"counts": weights_info, "warnings": warnings, "route": m.route,
                                         "source": track.source,
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
