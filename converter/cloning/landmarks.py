"""Automatic correspondences in the spirit of chapter 11.6: geometric rules on a face looking down +z, y up.

Profiles are sampled by casting rays at the surface (so the rules do not depend on tessellation): the
centreline profile z(y) through the nose tip gives the nose top, nose bottom, lips, mouth, chin and throat
as its successive extremes; horizontal profiles from the centreline outward give the eye sockets, nose
wings, mouth corners and cheeks. A few proportional points (a grid scaled by the found features) are
added so that the volume morph has support over the whole face, and the lip contact line (upper/lower
lip vertices that nearly touch with opposed normals) is found for the mouth handling of 11.5.

Every threshold is a fraction of the face's size (the mesh's height for the profile down the middle, the
nose-top-to-chin height after that) and windows are counted in samples, so millimetre, centimetre and metre
meshes give the same points; nothing needs the back of the head, a neck or eye parts, so a front-only face
mask works. The points that only say how far the mesh extends (head top, sides, throat) are not matched
between faces. When the rules fail, the error names the face and the missing feature, and says how to turn
the face when it would work turned (looking down -z, or z-up).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from converter.animation import vertex_normals
from converter.cloning.surface import ray_cast
from converter.errors import InputError

SAMPLES = 240
EXTENT_POINTS = ("head_top", "side_right", "side_left", "throat")  # depend on how much of the head the mesh has
HINT = "make it look down +z with y up, or give --correspondences"
# Orientations tried when the rules fail, to tell the user how to turn the face: (description, rotation).
TURNS = (
    ("it looks down -z; turn it 180 degrees about y", np.diag([-1.0, 1.0, -1.0])),
    ("it is z-up looking down -y (Blender's convention); turn it to y up",
     np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])),
    ("it is z-up looking down +y; turn it to y up", np.array([[-1.0, 0, 0], [0, 0, 1], [0, 1, 0]])),
)


def _front_hits(verts: np.ndarray, faces: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Surface z seen from the front at points xy (n, 2); nan where the ray misses."""
    zmax = verts[:, 2].max() + 0.05 * max(float(np.ptp(verts, axis=0).max()), 1e-12)
    tri = verts[faces]
    lo, hi = tri[:, :, :2].min(1), tri[:, :, :2].max(1)
    box_lo, box_hi = xy.min(0), xy.max(0)
    near = ((hi >= box_lo) & (lo <= box_hi)).all(1)  # only triangles under the profile's bounding box
    sub = faces[near]
    if not len(sub):
        return np.full(len(xy), np.nan)
    origins = np.column_stack([xy, np.full(len(xy), zmax)])
    dirs = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
    return zmax - ray_cast(origins, dirs, verts, sub)


def _filled(z: np.ndarray) -> np.ndarray:
    ok = np.isfinite(z)
    if ok.sum() < 2:
        return np.nan_to_num(z)
    i = np.arange(len(z))
    return np.interp(i, i[ok], z[ok])


def _peaks(z: np.ndarray, prominence: float) -> np.ndarray:
    """Indices of the local maxima of z that stand out by at least `prominence`."""
    # scipy.signal costs ~0.9 s at import, half of `import converter.convert`: only landmark detection needs it.
    from scipy.signal import find_peaks  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    return find_peaks(z, prominence=prominence)[0]


def _extremes(z: np.ndarray, prominence: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices of local maxima and minima of a profile that stand out by at least `prominence`."""
    zf = _filled(z)
    return _peaks(zf, prominence), _peaks(-zf, prominence)


def _first_after(idx: np.ndarray, start: int, step: int) -> int | None:
    """The first index in idx strictly beyond start in direction step (+1 or -1)."""
    c = idx[idx > start] if step > 0 else idx[idx < start][::-1]
    return int(c[0]) if len(c) else None


class NotFound(Exception):
    """A rule found no feature: what is missing and why (worded for the user)."""


def detect(verts: np.ndarray, faces: np.ndarray, name: str = "face") -> dict[str, np.ndarray]:
    """Named 3D feature points on a neutral face; InputError naming the face and what is missing on failure."""
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces)
    try:
        return _detect(verts, faces)
    except NotFound as exc:
        why = str(exc)
    turn = None
    if len(faces) and np.isfinite(verts).all():
        for text, rot in TURNS:
            try:
                _detect(verts @ rot.T, faces)
            except NotFound:
                continue
            turn = text
            break
    advice = f"{turn}, or give --correspondences" if turn else HINT
    raise InputError(f"cannot place landmarks on {name!r} automatically: {why}; {advice}.")


def _detect(verts: np.ndarray, faces: np.ndarray) -> dict[str, np.ndarray]:
    """The rules of detect(); NotFound when the nose or chin is missing."""
    if not len(faces):
        raise NotFound("no nose tip: the mesh has no triangles")
    used = np.unique(faces)
    v = verts[used]
    if not np.isfinite(v).all():
        raise NotFound("no nose tip: some vertices are not finite numbers")
    ext = np.ptp(v, axis=0)
    if ext[2] < 0.05 * max(ext[0], ext[1]) or min(ext[0], ext[1]) <= 0:
        raise NotFound("no nose tip: the mesh is flat, with no depth along z")
    tip = v[np.argmax(v[:, 2])].copy()
    mid = 0.5 * (v.max(0) + v.min(0))
    rel_y = (tip[1] - v[:, 1].min()) / ext[1]
    if abs(tip[0] - mid[0]) > 0.15 * ext[0] or not 0.2 <= rel_y <= 0.9:
        raise NotFound("no nose tip: the mesh has no clear forward-most point near its centre")
    tip[0] = mid[0]  # the centreline: a face is near symmetric
    height = ext[1]
    pts: dict[str, np.ndarray] = {
        "nose_tip": v[np.argmax(v[:, 2])], "head_top": v[np.argmax(v[:, 1])],
        "side_right": v[np.argmax(v[:, 0])], "side_left": v[np.argmin(v[:, 0])],
    }
    ys = np.linspace(v[:, 1].min(), v[:, 1].max(), SAMPLES)
    zc = _front_hits(verts, faces, np.column_stack([np.full(SAMPLES, tip[0]), ys]))
    prom = 0.0015 * height
    mx, mn = _extremes(zc, prom)
    i_tip = int(np.argmin(np.abs(ys - tip[1])))

    def centre(name: str, i: int | None) -> int | None:
        if i is not None and np.isfinite(zc[i]):
            pts[name] = np.array([tip[0], ys[i], zc[i]])
        return i

    i_top = centre("nose_top", _first_after(mn, i_tip, +1))
    if i_top is not None:
        centre("glabella", _first_after(mx, i_top, +1))
    i = centre("nose_bottom", _first_after(mn, i_tip, -1))
    i_chin = None
    if i is not None:
        i = centre("lip_top", _first_after(mx, i, -1))
    if i is not None:
        i = centre("mouth", _first_after(mn, i, -1))
    if i is not None:
        i = centre("lip_bottom", _first_after(mx, i, -1))
    if i is not None:
        # Rules 13-15 on a coarse mesh: the chin is the most forward point from a third of a nose-top-to-
        # lower-lip span below the lower lip down to one span (and above the throat, the deepest point below
        # it, if the mesh has a neck), the fold the deepest point above the chin. In spans, not down to the
        # mesh's lower edge, so the chin does not depend on how much neck the mesh has; the window's top
        # keeps the chin on the same spot of a flat chin front on fine and coarse meshes.
        zf = _filled(zc)
        big = _peaks(-zf, 0.05 * height)
        i_throat = _first_after(big, i, -1)
        n_span = i_top - i if i_top is not None else SAMPLES // 4  # in samples: exact at any scale
        span = (ys[1] - ys[0]) * n_span
        lo = max(i - n_span, 0 if i_throat is None else i_throat)
        top = i - max(1, round(n_span / 3))
        if top > lo:
            i_chin = lo + int(np.argmax(zf[lo:top]))
            centre("chin", i_chin)
            if i - i_chin > 2:
                j = i_chin + 1 + int(np.argmin(zf[i_chin + 1:i]))
                # A fold shallower than 1% of the span is no fold (a flat chin front): take the middle.
                flat = zf[j] > min(zf[i_chin], zf[i]) - 0.01 * span
                centre("lip_chin_fold", (i_chin + i) // 2 if flat else j)
            if i_throat is not None:
                centre("throat", i_throat)
    if "mouth" in pts and "lip_top" in pts and "lip_bottom" in pts:
        lips = 0.5 * (pts["lip_top"] + pts["lip_bottom"])
        if pts["mouth"][2] < lips[2] - 0.03 * height:  # the ray went through the lips' slit
            pts["mouth"] = np.array([tip[0], pts["mouth"][1], lips[2] - 0.01 * height])
    if "nose_top" not in pts:
        raise NotFound("no nose bridge: the profile down the middle of the face has no dip above its "
                       "forward-most point")
    if "chin" not in pts:
        raise NotFound("no chin: the profile down the middle of the face has no nose-lips-chin shape below "
                       "its forward-most point")
    # Sideways profiles reach 0.8 nose-top-to-chin heights out (a face's half width), not to the mesh's edge,
    # so a face mask cut before the ears samples the same points as a whole head.
    face_h = pts["nose_top"][1] - pts["chin"][1]  # the face's own size, whatever the mesh's extent
    half = 0.8 * face_h
    xs = np.linspace(0.0, half, SAMPLES // 2)

    def z_centre(y: float) -> float:
        return float(np.interp(y, ys, _filled(zc)))

    def sideways(name: str, y: float, kind: str) -> None:
        for sign, side in ((1, "right"), (-1, "left")):
            x = tip[0] + sign * xs
            z = _front_hits(verts, faces, np.column_stack([x, np.full(len(x), y)]))
            z[z < z_centre(y) - 0.25 * face_h] = np.nan  # through a hole (eye, mouth): not the skin
            if kind == "deepest":
                # The deepest skin point 0.1-0.3 face heights out: the same spot whether the socket holds an
                # eyeball (which bulges out of it) or is an open hole (rays through it were dropped above).
                win = np.where((xs >= 0.1 * face_h) & (xs <= 0.3 * face_h) & np.isfinite(z), z, np.inf)
                j = int(np.argmin(win)) if np.isfinite(win).any() else None
            else:
                mxs, mns = _extremes(z, prom)
                j = _first_after(mns if kind == "min" else mxs, 1, +1)
            if j is not None and np.isfinite(z[j]):
                pts[f"{name}_{side}"] = np.array([x[j], y, z[j]])

    y_top, y_tip = pts["nose_top"][1], tip[1]
    sideways("eye_socket", y_top - 0.25 * (y_top - y_tip), "deepest")
    if "nose_bottom" in pts:
        sideways("nose_wing", pts["nose_bottom"][1] + 0.3 * (y_tip - pts["nose_bottom"][1]), "min")
    sideways("cheek", y_tip, "max")
    # Proportional points: a grid spanned by the nose-top-to-chin height and a width in proportion to it
    # (the eye sockets' spacing on an average face; not measured, as eyeballs in the mesh would move it).
    y_chin = ys[i_chin]
    width = 0.42 * (y_top - y_chin)
    # Where a side rule found no extreme (a smooth or coarse face), place the point proportionally.
    fallback = {"nose_wing": (0.35, pts.get("nose_bottom", tip)[1] + 0.3 * (y_tip - pts.get("nose_bottom", tip)[1])),
                "mouth_side": (0.6, pts["mouth"][1] if "mouth" in pts else y_tip - 0.5 * (y_tip - ys[i_chin])),
                "eye_socket": (0.5, y_top - 0.25 * (y_top - y_tip))}
    for name, (fx, y) in fallback.items():
        for sign, side in ((1, "right"), (-1, "left")):
            if f"{name}_{side}" not in pts:
                z = _front_hits(verts, faces, np.array([[tip[0] + sign * fx * width, y]]))[0]
                if np.isfinite(z) and z > z_centre(y) - 0.25 * face_h:
                    pts[f"{name}_{side}"] = np.array([tip[0] + sign * fx * width, y, z])
    gx, gy = np.meshgrid(np.array([-1.5, -0.9, 0.9, 1.5]), np.array([1.3, 0.85, 0.4, 0.05, -0.1]))
    gxy = np.column_stack([tip[0] + gx.ravel() * width, y_chin + (y_top - y_chin) * gy.ravel()])
    gz = _front_hits(verts, faces, gxy)
    for k, (p, z) in enumerate(zip(gxy, gz)):
        if np.isfinite(z):
            pts[f"grid_{k:02d}"] = np.array([p[0], p[1], z])
    return pts


def lip_contact(verts: np.ndarray, faces: np.ndarray, pts: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Upper- and lower-lip contact-line vertex ids, each sorted left to right (empty when lips are joined).

    Rule 11 asks for the duplicated vertices: here, vertex pairs of the mouth region closer than 2% of
    the nose-to-chin height whose normals face each other.
    """
    empty = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if "mouth" not in pts or "nose_bottom" not in pts or "chin" not in pts:
        return empty
    m = pts["mouth"]
    h = pts["nose_bottom"][1] - pts["chin"][1]
    used = np.unique(faces)
    half_w = abs(pts["mouth_corner_right"][0] - pts["mouth_corner_left"][0]) * 0.6 + 0.05 * h \
        if "mouth_corner_right" in pts and "mouth_corner_left" in pts else 0.6 * h
    box = used[(np.abs(verts[used, 0] - m[0]) < half_w) & (np.abs(verts[used, 1] - m[1]) < 0.25 * h)]
    if len(box) < 4:
        return empty
    n = vertex_normals(verts[None].astype(np.float32), faces)[0][box]
    pairs = np.array(sorted(cKDTree(verts[box]).query_pairs(0.06 * h)), np.int64).reshape(-1, 2)
    if not len(pairs):
        return empty
    opposed = (n[pairs[:, 0]] * n[pairs[:, 1]]).sum(1) < -0.3
    pairs = pairs[opposed]
    a, b = box[pairs[:, 0]], box[pairs[:, 1]]
    # The upper lip's contact surface faces down.
    up = np.where(n[pairs[:, 0], 1] < n[pairs[:, 1], 1], a, b)
    lo = np.where(n[pairs[:, 0], 1] < n[pairs[:, 1], 1], b, a)
    up, lo = np.unique(up), np.unique(lo)
    if len(up) < 3 or len(lo) < 3:
        return empty
    return up[np.argsort(verts[up, 0], kind="stable")], lo[np.argsort(verts[lo, 0], kind="stable")]


def line_points(verts: np.ndarray, line: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Points at normalised arc-length params along a vertex polyline (eq. 11.16)."""
    p = verts[line].astype(np.float64)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    s = s / s[-1] if s[-1] > 0 else np.linspace(0, 1, len(p))
    return np.column_stack([np.interp(params, s, p[:, c]) for c in range(3)])


def matched(src_verts: np.ndarray, src_faces: np.ndarray, tgt_verts: np.ndarray, tgt_faces: np.ndarray,
            src_name: str = "source", tgt_name: str = "target"):
    """Corresponding point arrays (n, 3), (n, 3) and names from the rules applied to both faces."""
    a = detect(src_verts, src_faces, src_name)
    b = detect(tgt_verts, tgt_faces, tgt_name)
    names = [k for k in a if k in b and k not in EXTENT_POINTS
             and not any(np.allclose(a[k], a[j]) or np.allclose(b[k], b[j]) for j in a if j < k and j in b)]
    src = [a[k] for k in names]
    tgt = [b[k] for k in names]
    lu_a, ll_a = lip_contact(src_verts, src_faces, a)
    lu_b, ll_b = lip_contact(tgt_verts, tgt_faces, b)
    if len(lu_a) and len(lu_b):
        # Only the contact line's ends (the mouth corners, eq. 11.16 at s = 0 and 1) go into the morph: its
        # inner points are noisy on coarse meshes, and the projection keeps the lips apart by their normals.
        s = np.array([0.0, 1.0])
        for tag, la, lb in (("lip_corner", lu_a, lu_b),):
            src += list(line_points(src_verts, la, s))
            tgt += list(line_points(tgt_verts, lb, s))
            names += [f"{tag}_{k}" for k in range(len(s))]
    return np.array(src), np.array(tgt), names
