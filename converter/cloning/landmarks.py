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
mask works. On a coarse mask (a morphable model's few hundred vertices) the profile loses its smaller extremes:
the dip under the nose, the mouth's dip between merged lips; the lips are then placed in proportion to the nose
(or to the chin, where the profile shows it as a bump), on the nearest extreme of their kind. The points that
only say how far the mesh extends (head top, sides, throat) are not matched between faces. When the rules fail,
the error names the face and the missing landmark, says what to give with --correspondences instead, and how
to turn the face when it would work turned (looking down -z, or z-up); given correspondences, the points found
before the failure are kept and the user's pairs add the rest.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from converter.animation import vertex_normals
from converter.cloning.surface import ray_cast
from converter.errors import InputError

SAMPLES = 240
EXTENT_POINTS = ("head_top", "side_right", "side_left", "throat")  # depend on how much of the head the mesh has
# What a user gives instead of a missing landmark: pairs of points on the two faces, in the --correspondences file.
BY_HAND = ('--correspondences with a pair for the {what} and more spread over the face (a JSON file '
           '{{"pairs": [[source, target], ...]}}, each a vertex id or [x, y, z])')
# Proportions of the profile below the nose on an average face, for coarse meshes whose profile has lost the
# smaller extremes (the mouth's dip, the dip under the nose): the means of what the chain of extremes finds on the
# sample face, the ICT head and MediaPipe's canonical face. Lengths are in nose lengths (nose top to nose bottom):
# upper lip 0.14-0.29, mouth 0.25-0.43, lower lip 0.42-0.52 and chin 0.90-1.05 below the nose bottom; the nose
# bottom is 0.37-0.55 tip-to-nose-top lengths below the tip. Each lip is a bump (+1) or a dip (-1).
LIPS = (("lip_top", 0.2, 1), ("mouth", 0.33, -1), ("lip_bottom", 0.46, 1))
CHIN = 0.96
CHIN_RANGE = (0.75, 1.5)  # a bump of the profile this far below the nose bottom is the chin
LIPS_REACH = 0.8  # a chain whose lower lip is farther below the nose bottom took the chin for it
NOSE_REACH = 0.7  # a dip farther below the tip (in tip-to-nose-top lengths) is not the nose's bottom
NOSE_DEPTH = 1.5  # the nose's top and bottom lie behind its tip by at most this many tip-to-top lengths (0.4-0.7)
BEND = 0.15  # the least change of slope of a nose's top where the profile has no dip there
SNAP = 0.1  # a proportional lip point moves to an extreme of its kind this near (in nose lengths)
RELIEF = 0.03  # the least relief (in nose lengths) of the profile from the nose bottom down past the chin
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
    # scipy.signal is slow to import, much of `import converter.convert`'s time: only landmark detection needs it.
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
    """A rule found no feature: what is missing and why (worded for the user), and the points found before."""

    def __init__(self, what: str, why: str, found: dict[str, np.ndarray] | None = None):
        super().__init__(f"no {what}: {why}")
        self.what = what
        self.found = dict(found or {})


def detect(verts: np.ndarray, faces: np.ndarray, name: str = "face", partial: bool = False,
           by_hand: str = BY_HAND) -> dict[str, np.ndarray]:
    """Named 3D feature points on a neutral face; InputError naming the face, what is missing and (by_hand, with
    {what}) what to give instead on failure (with partial, the points found before the failure instead)."""
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces)
    try:
        return _detect(verts, faces)
    except NotFound as exc:
        if partial:
            return exc.found
        why, what = str(exc), exc.what
    turn = None
    if len(faces) and np.isfinite(verts).all():
        for text, rot in TURNS:
            try:
                _detect(verts @ rot.T, faces)
            except NotFound:
                continue
            turn = text
            break
    by_hand = by_hand.format(what=what)
    advice = f"{turn}, or give {by_hand}" if turn else f"make it look down +z with y up, or give {by_hand}"
    raise InputError(f"cannot place landmarks on {name!r} automatically: {why}; {advice}.")


def _centreline(verts: np.ndarray, faces: np.ndarray, tip: np.ndarray, mid: float, ext: np.ndarray) -> float:
    """x of the face's middle: the nose's, midway between where rows across it just above the tip fall 2% of the
    mesh's height behind their top (a mask cut unevenly is not centred on its box; a coarse mask's tip vertex
    can sit off the ridge); the box's middle mid where the rows show no nose at the tip."""
    rows = tip[1] + np.array([-0.01, 0.0, 0.02, 0.04]) * ext[1]
    xs = np.linspace(tip[0] - 0.15 * ext[0], tip[0] + 0.15 * ext[0], SAMPLES // 3)
    z = _front_hits(verts, faces, np.column_stack([np.tile(xs, len(rows)), np.repeat(rows, len(xs))]))
    centres = []
    for zr in z.reshape(len(rows), len(xs)):
        if not np.isfinite(zr).any():
            continue
        j = int(np.nanargmax(zr))
        low = ~(zr >= zr[j] - 0.02 * ext[1])  # nan counts as low
        left, right = np.flatnonzero(low[:j]), np.flatnonzero(low[j:])
        if len(left) and len(right):
            a, b = left[-1], j + right[0]  # the first samples below the level on either side
            centres.append(0.5 * (_crossing(xs, zr, a, a + 1, zr[j] - 0.02 * ext[1])
                                  + _crossing(xs, zr, b, b - 1, zr[j] - 0.02 * ext[1])))
    x = float(np.mean(centres)) if centres else mid
    return x if abs(x - tip[0]) < 0.05 * ext[0] else mid  # rows far off the tip did not cross a nose


def _crossing(xs: np.ndarray, z: np.ndarray, low: int, high: int, level: float) -> float:
    """x where z reaches level between sample low (below it, or nan) and its neighbour high (above it)."""
    if not np.isfinite(z[low]):
        return float(0.5 * (xs[low] + xs[high]))
    t = (level - z[low]) / (z[high] - z[low])
    return float(xs[low] + t * (xs[high] - xs[low]))


def _nose_top(zf: np.ndarray, mn: np.ndarray, i_tip: int, dy: float) -> int | None:
    """Profile index of the nose's top: the first dip above the tip, or on a coarse profile that runs from the nose
    straight up the forehead, where it bends most from the nose's slope to the forehead's (the largest change of
    slope over 1/40 of the profile, within 0.35 of it above the tip; a face's is 0.4-0.8, a convex shape's none).
    dy is the samples' spacing."""
    i = _first_after(mn, i_tip, +1)
    if i is not None:
        return i
    k = SAMPLES // 40
    d2 = np.full(len(zf), -np.inf)
    d2[k:-k] = zf[2 * k:] - 2 * zf[k:-k] + zf[:-2 * k]
    hi = min(i_tip + round(0.35 * SAMPLES), len(zf) - k)
    if hi <= i_tip + k:
        return None
    j = i_tip + k + int(np.argmax(d2[i_tip + k:hi]))
    return j if d2[j] > BEND * k * dy else None


def _nose_bottom(zf: np.ndarray, mn: np.ndarray, i_tip: int, i_top: int, dy: float) -> int | None:
    """Profile index of the nose's bottom: the first dip below the tip, or on a coarse profile that runs from the
    nose's underside straight into the upper lip, the point farthest behind the line from the tip down one
    tip-to-nose-top length (None when the mesh ends before that)."""
    n = i_top - i_tip
    i = _first_after(mn, i_tip, -1)
    if i is not None and i_tip - i <= NOSE_REACH * n:
        return i
    j = i_tip - n
    if j < 0:
        return None
    seg = zf[j:i_tip + 1]
    behind = seg - np.linspace(seg[0], seg[-1], len(seg))
    i = int(np.argmin(behind))
    return j + i if behind[i] < -0.05 * dy * n else None  # 0.2-0.3 tip-to-top lengths behind on a face


def _chain(mx: np.ndarray, mn: np.ndarray, i_nb: int) -> tuple[int, int, int] | None:
    """Profile indices of the upper lip, mouth and lower lip as the extremes after the nose bottom i_nb: a bump,
    a dip, a bump (None when the profile has fewer)."""
    i_lt = _first_after(mx, i_nb, -1)
    i_m = None if i_lt is None else _first_after(mn, i_lt, -1)
    i_lb = None if i_m is None else _first_after(mx, i_m, -1)
    return None if i_lb is None else (i_lt, i_m, i_lb)


def _proportional(zc: np.ndarray, mx: np.ndarray, mn: np.ndarray, i_nb: int,
                  n_nose: int) -> tuple[int, int, int, int | None]:
    """Profile indices of the upper lip, mouth and lower lip placed in proportion below the nose bottom i_nb (the
    lower lip's may be below 0: the mesh ends above it), and of the chin where the profile shows it as a bump."""
    # A coarse mesh (a few vertices across the lips) merges the lips or loses the mouth's dip, and the chain of
    # extremes runs on to the chin: place the lips between the nose and the chin where the chin is a bump of the
    # profile, else by the nose's length; each on the nearest extreme of its kind where the profile has one (for
    # the mouth, also the middle of a gap the rays went through).
    below = i_nb - mx
    chin = mx[(below >= CHIN_RANGE[0] * n_nose) & (below <= CHIN_RANGE[1] * n_nose)]
    i_chin = int(chin[0]) if len(chin) else None  # the first bump in range: a lower one is on the neck
    unit = n_nose if i_chin is None else (i_nb - i_chin) / CHIN
    gap = np.diff(np.r_[0, np.isnan(zc).astype(np.int8), 0])
    dips = np.union1d(mn, (np.flatnonzero(gap == 1) + np.flatnonzero(gap == -1) - 1) // 2)
    out, prev = [], i_nb
    for _, frac, kind in LIPS:
        want = min(i_nb - round(frac * unit), prev - 1)
        cand = mx if kind > 0 else dips
        cand = cand[(cand < prev) & (np.abs(cand - want) <= SNAP * unit)]
        prev = int(cand[np.argmin(np.abs(cand - want))]) if len(cand) else want
        out.append(prev)
    if i_chin is not None and i_chin >= out[2]:
        i_chin = None
    return out[0], out[1], out[2], i_chin


def _chin_window(zf: np.ndarray, i_lb: int, i_top: int, height: float) -> tuple[int, int, int | None]:
    """Rules 13-15 on a coarse mesh: (lo, top, throat) where the chin is the most forward point of zf[lo:top]."""
    # From a third of a nose-top-to-lower-lip span below the lower lip down to one span, and above the throat
    # (the deepest point below it) if the mesh has a neck. In spans, not down to the mesh's lower edge, so the
    # chin does not depend on how much neck the mesh has; the window's top keeps the chin on the same spot of a
    # flat chin front on fine and coarse meshes. Empty (top <= lo) when the mesh ends above it.
    n_span = i_top - i_lb
    i_throat = _first_after(_peaks(-zf, 0.05 * height), i_lb, -1) if i_lb > 0 else None
    lo = max(i_lb - n_span, 0 if i_throat is None else i_throat)
    return lo, i_lb - max(1, round(n_span / 3)), i_throat


def _detect(verts: np.ndarray, faces: np.ndarray) -> dict[str, np.ndarray]:
    """The rules of detect(); NotFound when the nose or chin is missing."""
    if not len(faces):
        raise NotFound("nose tip", "the mesh has no triangles")
    used = np.unique(faces)
    v = verts[used]
    if not np.isfinite(v).all():
        raise NotFound("nose tip", "some vertices are not finite numbers")
    ext = np.ptp(v, axis=0)
    if ext[2] < 0.05 * max(ext[0], ext[1]) or min(ext[0], ext[1]) <= 0:
        raise NotFound("nose tip", "the mesh is flat, with no depth along z")
    tip = v[np.argmax(v[:, 2])].copy()
    mid = 0.5 * (v.max(0) + v.min(0))
    rel_y = (tip[1] - v[:, 1].min()) / ext[1]
    if abs(tip[0] - mid[0]) > 0.15 * ext[0] or not 0.2 <= rel_y <= 0.9:
        raise NotFound("nose tip", "the mesh has no clear forward-most point near its centre")
    tip[0] = _centreline(verts, faces, tip, mid[0], ext)
    height = ext[1]
    pts: dict[str, np.ndarray] = {
        "nose_tip": v[np.argmax(v[:, 2])], "head_top": v[np.argmax(v[:, 1])],
        "side_right": v[np.argmax(v[:, 0])], "side_left": v[np.argmin(v[:, 0])],
    }
    ys = np.linspace(v[:, 1].min(), v[:, 1].max(), SAMPLES)
    zc = _front_hits(verts, faces, np.column_stack([np.full(SAMPLES, tip[0]), ys]))
    zf = _filled(zc)
    prom = 0.0015 * height
    mx, mn = _extremes(zc, prom)
    i_tip = int(np.argmin(np.abs(ys - tip[1])))

    def centre(name: str, i: int | None, profile: np.ndarray = zc) -> int | None:
        if i is not None and 0 <= i < SAMPLES and np.isfinite(profile[i]):
            pts[name] = np.array([tip[0], ys[i], profile[i]])
        return i

    i_top = centre("nose_top", _nose_top(zf, mn, i_tip, ys[1] - ys[0]))
    if i_top is not None:
        centre("glabella", _first_after(mx, i_top, +1))
    if "nose_top" not in pts:
        raise NotFound("nose bridge", "the profile down the middle of the face has no dip above its forward-most "
                       "point", pts)
    # A dip far behind the tip (a head seen from below or above has one) is no nose's bridge.
    nose_h = ys[i_top] - ys[i_tip]
    if tip[2] - zf[i_top] > NOSE_DEPTH * nose_h:
        for name in ("nose_top", "glabella"):
            pts.pop(name, None)
        raise NotFound("nose bridge", "the dip above the forward-most point of the profile down the middle of the "
                       "face is deeper than a nose is long", pts)
    i_nb = centre("nose_bottom", _nose_bottom(zf, mn, i_tip, i_top, ys[1] - ys[0]))
    if "nose_bottom" in pts and tip[2] - zf[i_nb] > NOSE_DEPTH * nose_h:
        del pts["nose_bottom"]
    if "nose_bottom" not in pts:
        raise NotFound("chin", "the profile down the middle of the face has no nose-lips-chin shape below its "
                       "forward-most point", pts)
    n_nose = i_top - i_nb  # the nose's length in samples: exact at any scale
    nose_len = ys[i_top] - ys[i_nb]
    # The chain of extremes, if its chin is one: not past the lips' reach, with a chin at most 1.5 nose lengths
    # below the nose and half of one behind the lower lip (else the chain took the chin for the lower lip and
    # the window below it holds the neck); in proportion otherwise.
    chain, i_bump = _chain(mx, mn, i_nb), None
    if chain is not None and i_nb - chain[2] <= LIPS_REACH * n_nose:
        lo, top, _ = _chin_window(zf, chain[2], i_top, height)
        i_c = lo + int(np.argmax(zf[lo:top])) if top > lo else None
        if i_c is None or i_nb - i_c > CHIN_RANGE[1] * n_nose or zf[chain[2]] - zf[i_c] > 0.5 * nose_len:
            chain = None
    else:
        chain = None
    if chain is None:
        *chain, i_bump = _proportional(zc, mx, mn, i_nb, n_nose)
    for name, i in zip(("lip_top", "mouth", "lip_bottom"), chain):
        centre(name, i, zf)  # filled: an open mouth's gap
    if "mouth" in pts and "lip_top" in pts and "lip_bottom" in pts:
        lips = 0.5 * (pts["lip_top"] + pts["lip_bottom"])
        if pts["mouth"][2] < lips[2] - 0.03 * height:  # the ray went through the lips' slit
            pts["mouth"] = np.array([tip[0], pts["mouth"][1], lips[2] - 0.01 * height])
    i = chain[2]
    lo, top, i_throat = _chin_window(zf, i, i_top, height)
    if i_bump is None and top <= lo:
        below = (ys[i_nb] - ys[0]) / nose_len
        raise NotFound("chin", f"the mesh ends {below:.2g} nose lengths below the nose's bottom, where a chin is "
                       f"about one", pts)
    # A face has lips and a chin standing off the line from the nose's bottom down past the chin; a profile that
    # keeps to that line (a lower face flattened or cut off by a plane) has neither.
    lo = min(lo, i_bump) if i_bump is not None else lo
    seg = zf[lo:i_nb + 1]
    if np.abs(seg - np.linspace(seg[0], seg[-1], len(seg))).max() < RELIEF * nose_len:
        raise NotFound("chin", "the profile down the middle of the face is flat below the nose, with no lips or "
                       "chin standing out", pts)
    i_chin = lo + int(np.argmax(zf[lo:top])) if i_bump is None else i_bump
    centre("chin", i_chin, zf)
    if i - i_chin > 2:
        j = i_chin + 1 + int(np.argmin(zf[i_chin + 1:i]))
        # A fold shallower than 1% of the span is no fold (a flat chin front): take the middle.
        flat = zf[j] > min(zf[i_chin], zf[i]) - 0.01 * (ys[i_top] - ys[i])
        centre("lip_chin_fold", (i_chin + i) // 2 if flat else j)
    if i_throat is not None:
        centre("throat", i_throat)
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
                if j is not None:
                    # The middle of the socket's floor (its points within 1% of a face height of the deepest):
                    # a flat floor's deepest point moves far with small changes of a coarse mesh.
                    off = np.flatnonzero(win > win[j] + 0.01 * face_h)
                    left, right = off[off < j], off[off > j]
                    j = ((left[-1] + 1 if len(left) else 0) + (right[0] - 1 if len(right) else len(win) - 1)) // 2
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
            src_name: str = "source", tgt_name: str = "target", partial: bool = False):
    """Corresponding point arrays (n, 3), (n, 3) and names from the rules applied to both faces (with partial,
    only the points found on both where the rules fail on one)."""
    a = detect(src_verts, src_faces, src_name, partial)
    b = detect(tgt_verts, tgt_faces, tgt_name, partial)
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
    return np.array(src).reshape(-1, 3), np.array(tgt).reshape(-1, 3), names
