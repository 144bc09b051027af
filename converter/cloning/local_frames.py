"""Cloning with local reference frames per face region (seed 003): same topology, five regions.

Each region (eyebrows, eyes, mouth, nose, face) has base points bp1..bp4 on the source base and the
same vertices on the target base: bp1 is the origin, bp2 - bp1 and bp3 - bp1 the (not necessarily
orthogonal) X and Y axes, their cross product Z, and bp4 the w-point. A source displacement in local
coordinates is divided by the source w-point's local coordinates and multiplied by the target's
(eq. 4-5), then taken back to world coordinates on the target's frame (eq. 6-8).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from converter.animation import FaceAnimation
from converter.cloning import dense, landmarks, rigid
from converter.errors import InputError

REGIONS = ("eyebrows", "eyes", "mouth", "nose", "face")
# Base points per region (bp1 origin, bp2 -> X, bp3 -> Y, bp4 w-point), as landmark names.
BASE_POINTS = {
    "eyebrows": ("nose_tip", "grid_02", "grid_01", "glabella"),
    "eyes": ("nose_tip", "grid_06", "grid_05", "nose_top"),
    "mouth": ("nose_top", "lip_corner_1", "lip_corner_0", "mouth"),
    "nose": ("nose_top", "nose_wing_right", "nose_wing_left", "nose_tip"),
    "face": ("nose_top", "grid_10", "grid_09", "chin"),
}
# Landmarks whose neighbourhood makes up each region (the rest is "face").
ANCHORS = {
    "eyebrows": ("glabella", "grid_01", "grid_02"),
    "eyes": ("eye_socket_right", "eye_socket_left", "grid_05", "grid_06"),
    "mouth": ("lip_top", "mouth", "lip_bottom", "lip_corner_0", "lip_corner_1"),
    "nose": ("nose_tip", "nose_bottom", "nose_wing_right", "nose_wing_left", "nose_top"),
}


def frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(origin, D) of a local frame from base points (4, 3): rows of D are the unit X, Y, Z axes."""
    x = points[1] - points[0]
    y = points[2] - points[0]
    z = np.cross(x, y)
    n = np.array([np.linalg.norm(x), np.linalg.norm(y), np.linalg.norm(z)])
    if (n < 1e-9 * max(np.ptp(points, axis=0).max(), 1e-12)).any() or n[2] < 1e-3 * n[0] * n[1]:
        raise InputError("the base points of a face region are degenerate (coincident or on one line); give "
                         "other landmarks with --correspondences.")
    return points[0], np.stack([x / n[0], y / n[1], z / n[2]])


def ratio(w_src: np.ndarray, w_tgt: np.ndarray) -> np.ndarray:
    """Per-axis w-point ratio; an axis where the source w-point has ~no extent uses the ratio of lengths."""
    whole = np.linalg.norm(w_tgt) / max(np.linalg.norm(w_src), 1e-12)
    small = np.abs(w_src) < 0.2 * np.abs(w_src).max()
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(small, whole, np.abs(w_tgt) / np.abs(w_src))
    return np.clip(r, whole / 3, whole * 3)  # a w-point far off in one axis must not blow the motion up

BY_HAND = ('--correspondences with the {what} and the other landmarks by name (a JSON file {{"landmarks": '
           '{{name: vertex id}}}}), or clone with the dense method')


def landmark_ids(verts: np.ndarray, faces: np.ndarray, correspondences: str | None,
                 name: str = "source") -> dict[str, int]:
    """Landmark name -> vertex id on the source base (automatic; a JSON {"landmarks": {name: id}} overrides)."""
    # the user's landmarks fill in what cannot be found; this method takes them by name, not as pairs
    pts = landmarks.detect(verts, faces, name, partial=bool(correspondences), by_hand=BY_HAND)
    up, lo = landmarks.lip_contact(verts, faces, pts)
    if len(up):
        pts["lip_corner_0"], pts["lip_corner_1"] = verts[up[0]], verts[up[-1]]
    elif "mouth_side_left" in pts and "mouth_side_right" in pts:
        pts["lip_corner_0"], pts["lip_corner_1"] = pts["mouth_side_left"], pts["mouth_side_right"]
    used = np.unique(faces)
    tree = cKDTree(verts[used])
    ids = {k: int(used[tree.query(p)[1]]) for k, p in pts.items()}
    if correspondences:

        try:
            extra = json.loads(Path(correspondences).read_text()).get("landmarks", {})
        except (OSError, ValueError, AttributeError) as exc:
            raise InputError(f"cannot read landmarks from {correspondences}: {exc}.") from None
        for k, v in extra.items():
            if not isinstance(v, int) or not 0 <= v < len(verts):
                raise InputError(f"landmark {k!r} must be a vertex id in 0..{len(verts) - 1}.")
            ids[k] = v
    return ids


def regions(verts: np.ndarray, ids: dict[str, int], size: float) -> np.ndarray:
    """Region index per vertex: the region of the nearest anchor landmark within reach, else face."""
    names, pos = [], []
    for r, anchors in ANCHORS.items():
        for a in anchors:
            if a in ids:
                names.append(REGIONS.index(r))
                pos.append(verts[ids[a]])
    label = np.full(len(verts), REGIONS.index("face"))
    if pos:
        d, j = cKDTree(np.array(pos)).query(verts)
        near = d < 0.12 * size
        label[near] = np.array(names)[j[near]]
    return label


def matrices(s_base: np.ndarray, t_base: np.ndarray, ids: dict[str, int]) -> np.ndarray:
    """Per-region 3x3 maps (5, 3, 3) from a source displacement to a target displacement."""
    out = []
    for r in REGIONS:
        names = BASE_POINTS[r]
        missing = [n for n in names if n not in ids]
        if missing:
            raise InputError(f"could not find the {r} base point(s) {', '.join(missing)} automatically; give them "
                             "as {\"landmarks\": {name: vertex id}} with --correspondences.")
        bp = [ids[n] for n in names]
        o_s, d_s = frame(s_base[bp])
        o_t, d_t = frame(t_base[bp])
        w_s, w_t = d_s @ (s_base[bp[3]] - o_s), d_t @ (t_base[bp[3]] - o_t)
        # local = D (p - o); scaled by the w-point ratio; back to world with D^-1 (eq. 8).
        out.append(np.linalg.solve(d_t, np.diag(ratio(w_s, w_t)) @ d_s))
    return np.stack(out)


def clone(source: FaceAnimation, target: FaceAnimation, correspondences: str | None = None) -> np.ndarray:
    """Target frames for head-frame source frames; source and target share one topology."""
    s_base = source.frames[0].astype(np.float64)
    t_base = target.frames[0].astype(np.float64)
    faces = dense.skin_faces(source)
    size = np.ptp(s_base[np.unique(faces)], axis=0).max()
    ids = landmark_ids(s_base, faces, correspondences, source.name)
    label = regions(s_base, ids, size)
    m = matrices(s_base, t_base, ids)
    disp = source.frames - source.frames[0]
    out = (t_base + np.einsum("vij,tvj->tvi", m[label], disp)).astype(np.float32)
    scale = np.sqrt(((t_base - t_base.mean(0)) ** 2).sum() / ((s_base - s_base.mean(0)) ** 2).sum())
    for _, comp in rigid.components(source.faces, source.part_ids, source.parts, source.n_vertices):
        out[:, comp] = rigid.transfer_rigid(source.frames, comp, t_base, comp, scale)
    return out
