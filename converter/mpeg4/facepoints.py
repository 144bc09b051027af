"""Feature points for known faces: Multi-PIE landmark ids (the ICT FaceKit head: samples/ict_fdp.py), the MediaPipe
canonical face, and the geometric rules that complete an FDP from a few key points (shared with `fdp --auto`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from converter.formats.obj import parse_obj
from converter.mpeg4.fdp import Fdp, fapu_from_points

# Multi-PIE 68 landmark index -> MPEG-4 feature point (l = the face's left, +x). Pairs of landmarks mean the skin
# vertex nearest their midpoint.
MULTIPIE_TO_FDP: dict[str, tuple[int, ...]] = {
    "2.1": (8,), "2.2": (62,), "2.3": (66,), "2.4": (64,), "2.5": (60,), "2.6": (63,), "2.7": (61,), "2.8": (65,),
    "2.9": (67,), "2.11": (9,), "2.12": (7,), "2.13": (12,), "2.14": (4,),
    "3.1": (43, 44), "3.2": (37, 38), "3.3": (46, 47), "3.4": (40, 41), "3.7": (45,), "3.8": (36,), "3.11": (42,),
    "3.12": (39,),
    "4.1": (22,), "4.2": (21,), "4.3": (24,), "4.4": (19,), "4.5": (26,), "4.6": (17,),
    "8.1": (51,), "8.2": (57,), "8.3": (54,), "8.4": (48,), "8.5": (52, 53), "8.6": (49, 50), "8.7": (55, 56),
    "8.8": (58, 59), "8.9": (50,), "8.10": (52,),
    "9.1": (35,), "9.2": (31,), "9.3": (30,), "9.4": (32,), "9.5": (34,), "9.12": (28,), "9.15": (33,),
}

# MediaPipe canonical face (468 vertices, 478 with irises) vertex ids per feature point; tuples as above.
MEDIAPIPE_TO_FDP: dict[str, tuple[int, ...]] = {
    "2.1": (152,), "2.2": (13,), "2.3": (14,), "2.4": (308,), "2.5": (78,), "2.6": (311,), "2.7": (81,),
    "2.8": (402,), "2.9": (178,), "2.11": (400,), "2.12": (176,), "2.13": (397,), "2.14": (172,),
    "3.1": (386,), "3.2": (159,), "3.3": (374,), "3.4": (145,), "3.7": (263,), "3.8": (33,), "3.11": (362,),
    "3.12": (133,),
    "4.1": (336,), "4.2": (107,), "4.3": (334,), "4.4": (105,), "4.5": (300,), "4.6": (70,),
    "8.1": (0,), "8.2": (17,), "8.3": (291,), "8.4": (61,), "8.5": (269,), "8.6": (39,), "8.7": (405,), "8.8": (181,),
    "8.9": (37,), "8.10": (267,),
    "9.1": (358,), "9.2": (129,), "9.3": (4,), "9.4": (98,), "9.5": (327,), "9.15": (2,), "11.1": (10,),
}
MEDIAPIPE_IRIS = {"left_eye": range(473, 478), "right_eye": range(468, 473)}


def nearest(vertices: np.ndarray, candidates: np.ndarray, p: np.ndarray) -> int:
    """The candidate vertex id nearest to point p."""
    return int(candidates[np.argmin(np.linalg.norm(vertices[candidates] - p, axis=1))])


def surface_point(vertices: np.ndarray, skin: np.ndarray, x: float, y: float, front: float | None = None) -> int:
    """The front-most skin vertex near (x, y) in the face plane (within 1% of the mesh height, else the nearest)."""
    p = vertices[skin]
    if front is not None and (p[:, 2] > front).any():
        ok = p[:, 2] > front
        skin, p = skin[ok], p[ok]
    dxy = np.hypot(p[:, 0] - x, p[:, 1] - y)
    close = dxy <= max(dxy.min(), 0.01 * np.ptp(vertices[:, 1]))
    return int(skin[close][np.argmax(p[close, 2])])


def complete_points(vertices: np.ndarray, skin: np.ndarray, pts: dict[str, int], parts: dict[str, list[int]]
                    ) -> dict[str, int]:
    """Add feature points that follow from the ones given by simple facial proportions (book section 11.6 style)."""
    out = dict(pts)
    v = vertices
    p = {k: v[i].astype(np.float64) for k, i in out.items()}
    front = None
    if "3.7" in p and "3.8" in p:
        front = min(p["3.7"][2], p["3.8"][2]) - 0.5 * abs(p["3.7"][0] - p["3.8"][0])
    for eye, (fp, _sign) in (("left_eye", ("3.5", 1)), ("right_eye", ("3.6", -1))):
        if fp not in out and eye in parts and len(parts[eye]):
            ids = np.asarray(parts[eye])
            out[fp] = int(ids[np.argmax(v[ids, 2])])  # pupil: the front-most point of the eyeball
            p[fp] = v[out[fp]].astype(np.float64)
    if "2.10" not in out and "2.1" in p and "8.2" in p:
        # the chin boss: most prominent midline point in the lower part between chin bottom and lower lip
        ys = np.linspace(p["2.1"][1], p["8.2"][1], 9)[1:6]
        cand = [surface_point(v, skin, 0.0, y, front) for y in ys]
        out["2.10"] = max(cand, key=lambda i: v[i, 2])
    if "9.15" in p and "3.7" in p and "3.8" in p:
        nose_y = p["9.15"][1]
        eye_y = (p["3.7"][1] + p["3.8"][1]) / 2
        for fp, side in (("5.1", "3.7"), ("5.2", "3.8")):
            if fp not in out and "2.4" in p:
                mouth_y = (p["2.4"][1] + nose_y) / 2
                out[fp] = surface_point(v, skin, 0.9 * p[side][0], mouth_y, front)
        for fp, side in (("5.3", "3.7"), ("5.4", "3.8")):
            if fp not in out:
                out[fp] = surface_point(v, skin, 0.85 * p[side][0], (eye_y + nose_y) / 2 - 0.1 * (eye_y - nose_y),
                                        front)
    for fp, (a, b) in {"3.9": ("3.3", "3.7"), "3.10": ("3.4", "3.8"), "3.13": ("3.1", "3.7"),
                       "3.14": ("3.2", "3.8")}.items():
        if fp not in out and a in p and b in p:
            # outer eyelid fold: beyond the lid margin, away from the eye centre
            centre = (p[a] + p[b]) / 2
            out[fp] = nearest(v, skin, p[a] + (p[a] - centre) * 0.6)
    return out


def ear_points(v: np.ndarray, skin: np.ndarray) -> dict[str, int]:
    """Ear feature points 10.1-10.6 on a head that has ears: the lateral-most skin, its top, back and lobe."""
    out = {}
    for sign, (top, back, lobe) in ((1, ("10.1", "10.3", "10.5")), (-1, ("10.2", "10.4", "10.6"))):
        side = skin[sign * v[skin, 0] > 0]
        xs = sign * v[side, 0]
        ear = side[xs > np.percentile(xs, 97)]
        if len(ear) < 10:
            continue
        out[top] = int(ear[np.argmax(v[ear, 1])])
        out[back] = int(ear[np.argmin(v[ear, 2])])
        out[lobe] = int(ear[np.argmin(v[ear, 1])])
    return out


def mediapipe_fdp(obj_path: str | Path) -> Fdp:
    """FDP of the MediaPipe canonical face (with or without the 10 iris vertices)."""
    v, f, _, _ = parse_obj(Path(obj_path).read_text(), Path(obj_path).name)
    v = v.astype(np.float64)
    iris = len(v) >= 478
    skin = np.unique(f[(f < 468).all(1)])
    pts: dict[str, int] = {}
    for fp, ids in MEDIAPIPE_TO_FDP.items():
        pts[fp] = ids[0] if len(ids) == 1 else nearest(v, skin, v[list(ids)].mean(0))
    parts: dict[str, list[int]] = {}
    if iris:
        parts = {k: list(r) for k, r in MEDIAPIPE_IRIS.items()}
        pts["3.5"], pts["3.6"] = 473, 468
    pts = complete_points(v, skin, pts, parts)
    fdp = Fdp(pts, parts, {}, {}, len(v), f"MediaPipe canonical face ({Path(obj_path).name}): known vertex ids + "
              "geometric rules (converter/mpeg4/facepoints.py)")
    pos = fdp.point_positions(v)
    if not iris:  # pupils from the eyelid points when the irises are absent
        pos["3.5"] = (pos["3.1"] + pos["3.3"]) / 2
        pos["3.6"] = (pos["3.2"] + pos["3.4"]) / 2
        fdp.positions = {"3.5": pos["3.5"].tolist(), "3.6": pos["3.6"].tolist()}
    fdp.fapu = fapu_from_points(v, pos)
    return fdp


def transfer_fdp(fdp: Fdp, src_vertices: np.ndarray, face) -> Fdp:
    """Map an FDP onto another mesh of the same face in the same coordinates (e.g. a decimated copy).

    A vertex of the target's non-skin parts joins the source part of its nearest source vertex; a feature point
    goes to the nearest target vertex of the same kind (skin, or the part the source point lies in).
    """
    from scipy.spatial import cKDTree  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    v = face.frames[0].astype(np.float64)
    skin_ids = [i for i, p in enumerate(face.parts) if p.name == "skin"]
    skin = np.unique(face.faces[np.isin(face.part_ids, skin_ids)])
    other = np.setdiff1d(np.unique(face.faces), skin)
    src_part = np.full(len(src_vertices), "", dtype=object)
    for name, ids in fdp.parts.items():
        src_part[np.asarray(ids, int)] = name
    _, nn = cKDTree(src_vertices).query(v[other])
    parts = {name: sorted(int(i) for i in other[src_part[nn] == name]) for name in fdp.parts}
    parts = {k: ids for k, ids in parts.items() if ids}
    points = {}
    for fp, i in fdp.points.items():
        kind = src_part[i]
        pool = skin if kind == "" else np.asarray(parts.get(kind, []), int)
        if pool.size:
            points[fp] = nearest(v, pool, src_vertices[i])
    out = Fdp(points, parts, {}, {}, len(v), f"{fdp.source}; mapped to {face.name} by nearest vertices "
              "(converter/mpeg4/facepoints.py transfer_fdp)")
    out.fapu = fapu_from_points(v, out.point_positions(v))
    return out
