"""`facesvg fdp --auto`: propose feature points for a new face from geometric heuristics (book section 11.6 spirit).

The face is assumed upright (y up) and looking along +z, as MPEG-4 neutral faces are. Eyes come from eyeball
parts (or eyeball-like loose shells); the nose tip is the front-most midline point; the midline profile below
it gives the nostril base, lips and chin; the rest follows from facial proportions relative to the eye
separation. Everything not found is reported, never silently invented.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.mpeg4.facepoints import complete_points, nearest, surface_point
from converter.mpeg4.fdp import Fdp, fapu_from_points
from converter.mpeg4.standard import FEATURE_POINTS
from converter.mpeg4.tables import sphere_center


@dataclass
class AutoReport:
    """What `fdp --auto` found, how, and what it could not find."""

    found: dict[str, str] = field(default_factory=dict)  # feature point or part -> how
    missing: dict[str, str] = field(default_factory=dict)  # feature point or part -> why

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        out = [f"found {len(self.found)} feature points/parts"]
        if self.missing:
            out.append(f"not found ({len(self.missing)}):")
            out += [f"  {k}: {why}" for k, why in sorted(self.missing.items(), key=lambda kv: _key(kv[0]))]
        return out


def _key(name: str):
    parts = name.split(".")
    return tuple(int(x) for x in parts) if all(x.isdigit() for x in parts) else (999, 0)


def _components(n: int, faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


def _eyeballs(v: np.ndarray, faces: np.ndarray, part_names: list[str], part_ids: np.ndarray, skin: np.ndarray,
              report: AutoReport) -> dict[str, np.ndarray]:
    """Left/right eyeball vertex ids: from 'eye'/'iris' parts, else from two sphere-like loose shells."""
    eye_parts = [i for i, n in enumerate(part_names) if n in ("eye", "iris", "eyes", "eyeball")]
    ids = np.unique(faces[np.isin(part_ids, eye_parts)]) if eye_parts else np.zeros(0, int)
    how = "eye parts of the mesh"
    if ids.size == 0:
        label = _components(len(v), faces)
        used = np.unique(faces)
        skin_labels = set(np.unique(label[skin]))
        cands = []
        for lab in np.unique(label[used]):
            if lab in skin_labels:
                continue
            c_ids = np.flatnonzero(label == lab)
            if len(c_ids) < 12:
                continue
            c = sphere_center(v[c_ids])
            r = np.linalg.norm(v[c_ids] - c, axis=1)
            width = np.ptp(v[skin, 0])
            upper = c[1] > np.percentile(v[skin, 1], 40)
            if upper and r.std() < 0.1 * r.mean() and 0.03 * width < r.mean() < 0.15 * width:
                cands.append((c_ids, c, r.mean()))
        ids = np.concatenate([c[0] for c in cands]) if cands else ids
        how = "sphere-like loose shells"
    x0 = (v[skin, 0].min() + v[skin, 0].max()) / 2
    out = {}
    for name, sel in (("left_eye", v[ids, 0] > x0), ("right_eye", v[ids, 0] < x0)):
        if sel.any():
            out[name] = ids[sel]
            report.found[name] = how
        else:
            report.missing[name] = "no eyeball part or sphere-like shell on this side"
    return out


def _eye_holes(v: np.ndarray, faces: np.ndarray, skin: np.ndarray, x0: float, width: float, report: AutoReport
               ) -> dict[str, np.ndarray]:
    """Vertex ids of the left/right eye openings: a symmetric pair of skin boundary loops in the upper face."""
    in_skin = np.zeros(len(v), bool)
    in_skin[skin] = True
    tri = faces[in_skin[faces].all(1)]
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    border = edges[count == 1]
    if len(border) == 0:
        return {}
    label = _components(len(v), np.c_[border, border[:, :1]])
    loops = [np.unique(border[label[border[:, 0]] == lab]) for lab in np.unique(label[border[:, 0]])]
    top = np.percentile(v[skin, 1], 40)
    cands = [lp for lp in loops if 6 <= len(lp) and np.ptp(v[lp, 0]) < 0.3 * width and v[lp, 1].mean() > top
             and abs(v[lp, 0].mean() - x0) > 0.08 * width]
    best = None
    for a in cands:
        for b in cands:
            ca, cb = v[a].mean(0), v[b].mean(0)
            if ca[0] > x0 > cb[0]:
                score = abs((ca[0] - x0) + (cb[0] - x0)) + abs(ca[1] - cb[1])
                if best is None or score < best[0]:
                    best = (score, a, b)
    if best is None or best[0] > 0.1 * width:
        return {}
    for k in ("left_eye", "right_eye"):
        report.missing[k] = "no eyeball; eye opening found instead (eyeball FAPs will not animate)"
    return {"left_eye": best[1], "right_eye": best[2]}


def _profile(v: np.ndarray, skin: np.ndarray, x0: float, band: float, y_lo: float, y_hi: float, bins: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The front midline profile: for each height bin, the front-most skin vertex near the midline."""
    mid = skin[np.abs(v[skin, 0] - x0) < band]
    mid = mid[(v[mid, 1] >= y_lo) & (v[mid, 1] <= y_hi)]
    edges = np.linspace(y_lo, y_hi, bins + 1)
    ys, zs, ids = [], [], []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = mid[(v[mid, 1] >= a) & (v[mid, 1] < b)]
        if sel.size:
            i = sel[np.argmax(v[sel, 2])]
            ys.append(v[i, 1])
            zs.append(v[i, 2])
            ids.append(i)
    return np.array(ys), np.array(zs), np.array(ids, int)


def auto_fdp(face: FaceAnimation) -> tuple[Fdp, AutoReport]:
    """Proposed FDP for the face's frame 0, with a report of what was found and what was not."""
    v = face.frames[0].astype(np.float64)
    faces = face.faces
    names = [p.name for p in face.parts]
    report = AutoReport()
    skin_parts = [i for i, n in enumerate(names) if n in ("skin", "face", "head")]
    skin = np.unique(faces[np.isin(face.part_ids, skin_parts)]) if skin_parts else np.zeros(0, int)
    if skin.size == 0:
        label = _components(len(v), faces)
        used = np.unique(faces)
        biggest = np.bincount(label[used]).argmax()
        skin = used[label[used] == biggest]
    width = float(np.ptp(v[skin, 0]))
    x0 = float((v[skin, 0].min() + v[skin, 0].max()) / 2)
    parts: dict[str, np.ndarray] = _eyeballs(v, faces, names, face.part_ids, skin, report)
    pts: dict[str, int] = {}
    pos: dict[str, np.ndarray] = {}

    # Pupils: the front-most point of each eyeball, else the middle of each eye opening (a hole in the skin).
    holes = {} if {"left_eye", "right_eye"} <= set(parts) else _eye_holes(v, faces, skin, x0, width, report)
    for eye, fp in (("left_eye", "3.5"), ("right_eye", "3.6")):
        if eye in parts:
            ids = parts[eye]
            pts[fp] = int(ids[np.argmax(v[ids, 2])])
            pos[fp] = v[pts[fp]]
            report.found[fp] = "front-most point of the eyeball"
        elif eye in holes:
            pos[fp] = v[holes[eye]].mean(0)
            report.found[fp] = "middle of the eye opening (given as a position)"
    if "3.5" not in pos or "3.6" not in pos:
        for fp in ("3.5", "3.6"):
            report.missing.setdefault(fp, "needs both eyeballs")
        raise InputError("could not find the eyes (no eye parts, eyeball-like shells or eye openings); write the FDP "
                         "by hand or start from samples/ict.fdp.json.")
    es = float(np.linalg.norm(pos["3.5"] - pos["3.6"]))
    eye_y = float((pos["3.5"][1] + pos["3.6"][1]) / 2)
    front = float(min(pos["3.5"][2], pos["3.6"][2]) - 0.9 * es)

    # Midline profile from the eyes down: nose tip, nostril base, lips, chin.
    # the midline band: 2% of the width, or wider on a coarse mesh so that it holds a vertex row
    tri = faces[np.isin(faces, skin).all(1)]
    edge = float(np.median(np.linalg.norm(v[tri[:, 0]] - v[tri[:, 1]], axis=1))) if len(tri) else 0.0
    ys, zs, ids = _profile(v, skin, x0, max(0.02 * width, 0.75 * edge), eye_y - 2.2 * es, eye_y, 120)
    ys, zs, ids = ys[::-1], zs[::-1], ids[::-1]  # top to bottom
    if len(ys) < 10:
        raise InputError("could not trace the face's midline profile below the eyes; is the face upright (y up)?")
    tip = int(np.argmax(zs))
    pts["9.3"] = int(ids[tip])
    report.found["9.3"] = "front-most midline point"

    def local(kind: str, start: int, stop_y: float) -> int | None:
        """Index of the first local min/max of z below start (down to stop_y)."""
        for k in range(start + 2, len(zs) - 2):
            if ys[k] < stop_y:
                return None
            win = zs[k - 2:k + 3]
            if (kind == "min" and zs[k] == win.min() and zs[k] < win.max() - 1e-6) or \
               (kind == "max" and zs[k] == win.max() and zs[k] > win.min() + 1e-6):
                return k
        return None

    steps = [("9.15", "min", "nostril base: first dip of the midline profile below the nose tip"),
             ("8.1", "max", "upper lip: next bulge"),
             ("2.2", "min", "lip contact: next dip"),
             ("8.2", "max", "lower lip: next bulge")]
    k = tip
    for fp, kind, how in steps:
        nk = local(kind, k, eye_y - 2.2 * es)
        if nk is None:
            report.missing[fp] = "the midline profile has no such dip/bulge"
            break
        k = nk
        if fp != "chin_groove":
            pts[fp] = int(ids[k])
            report.found[fp] = how
    if "8.2" in pts:
        # chin boss: the most prominent midline point from 0.15 eye separations below the lower lip down
        below = np.flatnonzero(ys < v[pts["8.2"], 1] - 0.15 * es)
        if below.size:
            pts["2.10"] = int(ids[below[np.argmax(zs[below])]])
            report.found["2.10"] = "chin boss: most prominent midline point below the lower lip"
    if "2.10" in pts:
        # chin bottom: where the profile below the chin boss has turned back by 30 degrees
        k10 = int(np.flatnonzero(ids == pts["2.10"])[0])
        for k in range(k10 + 1, len(zs)):
            dz, dy = zs[k10] - zs[k], ys[k10] - ys[k]
            if dz > 0.58 * dy:
                pts["2.1"] = int(ids[k])
                report.found["2.1"] = "chin bottom: the midline turns back under the chin"
                break
    if "2.1" not in pts:
        report.missing["2.1"] = "no chin bottom below the chin boss"
    if "2.2" in pts:
        pts["2.3"] = pts["2.2"]  # one contact point when the lips touch
        report.found["2.3"] = "same as 2.2 (closed mouth)"

    # Mouth corners and lip midpoints from proportions (mouth width ~ 0.78 eye separation).
    if "2.2" in pts:
        my = v[pts["2.2"], 1]
        half = 0.39 * es
        for fp, sx in (("2.4", 1), ("2.5", -1), ("8.3", 1), ("8.4", -1)):
            pts[fp] = surface_point(v, skin, x0 + sx * half, my, front)
            report.found[fp] = "mouth corner at 0.78 x eye separation"
        for fp, sx, ref in (("8.5", 1, "8.1"), ("8.6", -1, "8.1"), ("8.7", 1, "8.2"), ("8.8", -1, "8.2"),
                            ("2.6", 1, "2.2"), ("2.7", -1, "2.2"), ("2.8", 1, "2.3"), ("2.9", -1, "2.3")):
            if ref in pts:
                y = (v[pts[ref], 1] + my) / 2 if ref != "2.2" and ref != "2.3" else my
                pts[fp] = surface_point(v, skin, x0 + sx * half / 2, y, front)
                report.found[fp] = "half way between the lip middle and the corner"

    # Eyelids, eye corners and brows from each eyeball (or eye opening).
    for eye, side, names_ in (("left_eye", 1, ("3.1", "3.3", "3.7", "3.11", "4.1", "4.3", "4.5")),
                              ("right_eye", -1, ("3.2", "3.4", "3.8", "3.12", "4.2", "4.4", "4.6"))):
        up_, lo_, outer, inner, b_in, b_top, b_out = names_
        pupil = pos["3.5" if side > 0 else "3.6"]
        if eye in parts:
            ids = parts[eye]
            c = sphere_center(v[ids])
            r = float(np.linalg.norm(v[ids] - c, axis=1).mean())
            lid = lambda p: nearest(v, skin, p)  # noqa: E731
            pts[up_] = lid(pupil + np.array([0, 0.45 * r, 0.0]))
            pts[lo_] = lid(pupil - np.array([0, 0.45 * r, 0.0]))
            pts[outer] = lid(c + np.array([side * 1.05 * r, 0, 0.55 * r]))
            pts[inner] = lid(c + np.array([-side * 1.05 * r, 0, 0.55 * r]))
            how = "skin nearest to the eyeball at the lid margin"
        else:
            loop = holes[eye]
            near_mid = loop[np.abs(v[loop, 0] - pupil[0]) <= np.percentile(np.abs(v[loop, 0] - pupil[0]), 30)]
            pts[up_] = int(near_mid[np.argmax(v[near_mid, 1])])
            pts[lo_] = int(near_mid[np.argmin(v[near_mid, 1])])
            pts[outer] = int(loop[np.argmax(side * v[loop, 0])])
            pts[inner] = int(loop[np.argmin(side * v[loop, 0])])
            how = "on the rim of the eye opening"
        for fp in (up_, lo_, outer, inner):
            report.found[fp] = how
        px = pupil[0]
        pts[b_in] = surface_point(v, skin, px - side * 0.32 * es, eye_y + 0.36 * es, front)
        pts[b_top] = surface_point(v, skin, px + side * 0.09 * es, eye_y + 0.41 * es, front)
        pts[b_out] = surface_point(v, skin, px + side * 0.40 * es, eye_y + 0.25 * es, front)
        for fp in (b_in, b_top, b_out):
            report.found[fp] = "eyebrow by proportion of the eye separation"

    # Nose wings beside the nostril base.
    if "9.15" in pts:
        ny = v[pts["9.15"], 1]
        for fp, sx in (("9.1", 1), ("9.2", -1)):
            pts[fp] = surface_point(v, skin, x0 + sx * 0.19 * es, ny + 0.05 * es, front)
            report.found[fp] = "nostril wing by proportion"

    # More points by proportion of the eye separation (measured on the ICT FaceKit head's landmarks).
    rules = [("2.11", "2.1", 0.24, 0.05), ("2.12", "2.1", -0.24, 0.05), ("2.13", "2.1", 0.88, 0.48),
             ("2.14", "2.1", -0.88, 0.48), ("8.9", "8.1", -0.11, 0.01), ("8.10", "8.1", 0.11, 0.01),
             ("9.4", "9.15", -0.093, 0.01), ("9.5", "9.15", 0.093, 0.01)]
    for fp, ref, dx, dy in rules:
        if ref in pts and fp not in pts:
            pts[fp] = surface_point(v, skin, x0 + dx * es, v[pts[ref], 1] + dy * es, front)
            report.found[fp] = f"from {ref} by proportion of the eye separation"

    # Teeth and tongue from the mesh's parts, split at the lip contact height.
    mouth_y = v[pts["2.2"], 1] if "2.2" in pts else None
    teeth_parts = [i for i, n in enumerate(names) if n == "teeth"]
    inner_parts = [i for i, n in enumerate(names) if n in ("mouth", "tongue", "gums")]
    if mouth_y is not None and teeth_parts:
        t_ids = np.unique(faces[np.isin(face.part_ids, teeth_parts)])
        parts["upper_teeth"] = t_ids[v[t_ids, 1] >= mouth_y - 0.1 * es]
        parts["lower_teeth"] = t_ids[v[t_ids, 1] < mouth_y - 0.1 * es]
        report.found["upper_teeth"] = report.found["lower_teeth"] = "teeth part split at the lip contact"
    else:
        report.missing["upper_teeth"] = report.missing["lower_teeth"] = "no teeth part"
    if mouth_y is not None and inner_parts:
        m_ids = np.unique(faces[np.isin(face.part_ids, inner_parts)])
        low = m_ids[v[m_ids, 1] < mouth_y - 0.1 * es]
        if low.size:
            parts["tongue"] = low
            pts["6.1"] = int(low[np.argmax(v[low, 2])])
            report.found["tongue"] = report.found["6.1"] = "mouth part below the lip contact"
            top = low[v[low, 1] >= np.percentile(v[low, 1], 80)]
            pts["6.2"] = nearest(v, top, v[low].mean(0))
            pts["6.3"] = int(low[np.argmax(v[low, 0])])
            pts["6.4"] = int(low[np.argmin(v[low, 0])])
            for fp in ("6.2", "6.3", "6.4"):
                report.found[fp] = "tongue body centre and borders"
    if "tongue" not in parts:
        report.missing["tongue"] = "no mouth/tongue part"

    pts = complete_points(v, skin, pts, {k: list(x) for k, x in parts.items()})
    for fp in pts:
        report.found.setdefault(fp, "by proportion from the points above")
    for fp in FEATURE_POINTS:
        if fp not in pts and fp not in report.missing and not fp.startswith(("10.", "11.", "7.")):
            report.missing[fp] = "no heuristic"
    report.missing.setdefault("10.x", "ears are not looked for")
    positions = {k: [float(x) for x in pos[k]] for k in ("3.5", "3.6") if k not in pts}
    fdp = Fdp(pts, {k: sorted(int(i) for i in x) for k, x in parts.items()}, {}, positions, len(v),
              f"facesvg fdp --auto on {face.name}")
    fdp.fapu = fapu_from_points(v, fdp.point_positions(v))
    for k in ("MW0", "MNS0", "ENS0", "ES0", "IRISD0"):
        if k not in fdp.fapu:
            report.missing[k] = "needed feature points not found"
    return fdp, report
