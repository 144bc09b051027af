"""A tiny synthetic face and a stand-in FAP deformation, so the package can be tested apart from the engine."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from converter.animation import FaceAnimation, Part

FAPU = {"IRISD0": 0.1, "ES0": 0.7, "ENS0": 0.5, "MNS0": 0.3, "MW0": 0.6}
POINTS_XY = {
    "2.1": (0.0, -0.9), "2.2": (0.0, -0.42), "2.3": (0.0, -0.58), "8.3": (0.3, -0.5), "8.4": (-0.3, -0.5),
    "3.5": (0.35, 0.25), "3.6": (-0.35, 0.25), "3.1": (0.35, 0.36), "3.2": (-0.35, 0.36),
    "4.1": (0.15, 0.5), "4.2": (-0.15, 0.5), "9.3": (0.0, 0.0),
}
EYE_R = 0.12


def synthetic_face(n: int = 33) -> tuple[FaceAnimation, SimpleNamespace]:
    """A dome-shaped grid face (+z forward) with a mouth slit, teeth behind it, and two eye discs; and its FDP."""
    g = np.linspace(-1, 1, n)
    x, y = np.meshgrid(g, g[::-1])
    z = 0.6 * np.sqrt(np.clip(1.6 - x**2 - y**2, 0, None))
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1], i[1:, :-1], i[1:, 1:], i[:-1, 1:]  # y decreases down the rows
    quads = np.stack([a, b, c, d], -1).reshape(-1, 4)
    cen = v[quads].mean(1)
    slit = (np.abs(cen[:, 0]) < 0.25) & (np.abs(cen[:, 1] + 0.5) < 0.04)
    quads = quads[~slit]
    cen = cen[~slit]
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    cen2 = np.concatenate([cen, cen])
    eye = np.zeros(len(faces), bool)
    for ex, ey in (POINTS_XY["3.5"], POINTS_XY["3.6"]):
        eye |= np.hypot(cen2[:, 0] - ex, cen2[:, 1] - ey) < EYE_R
    part_ids = np.where(eye, 1, 0).astype(np.int32)
    # Teeth: a small flat strip behind the slit.
    tv = np.array([[-0.25, -0.44, 0.55], [-0.25, -0.6, 0.55], [0.25, -0.6, 0.55], [0.25, -0.44, 0.55]])
    base = len(v)
    v = np.concatenate([v, tv])
    faces = np.concatenate([faces, [[base, base + 1, base + 2], [base, base + 2, base + 3]]])
    part_ids = np.concatenate([part_ids, [2, 2]]).astype(np.int32)
    parts = (Part("skin", (0.85, 0.66, 0.55)), Part("eye", (0.95, 0.95, 0.93)), Part("teeth", (0.95, 0.93, 0.85)))
    anim = FaceAnimation(v[None].astype(np.float32), faces.astype(np.int32), part_ids, parts, 25.0, "synthetic")
    grid = v[:base]
    points = {k: int(np.argmin(np.hypot(grid[:, 0] - px, grid[:, 1] - py))) for k, (px, py) in POINTS_XY.items()}
    eye_ids = {}
    skin_faces, skin_parts = faces[: len(cen2)], part_ids[: len(cen2)]
    for name, key in (("left_eye", "3.5"), ("right_eye", "3.6")):
        ex, ey = POINTS_XY[key]
        near = (skin_parts == 1) & (np.hypot(cen2[:, 0] - ex, cen2[:, 1] - ey) < EYE_R)
        eye_ids[name] = np.unique(skin_faces[near]).tolist()
    fdp = SimpleNamespace(points=points, parts={**eye_ids, "upper_teeth": list(range(base, base + 4))}, fapu=dict(FAPU))
    return anim, fdp


def standin_deform(anim: FaceAnimation, fdp) -> callable:
    """values (K, 68) -> (K, V, 3): Gaussian pulls along each FAP's axis; eyeball yaw/pitch rotate the eye discs."""
    from converter.mpeg4.standard import fap_table, fapu_scale

    v0 = anim.frames[0].astype(np.float64)
    scale = fapu_scale(fdp.fapu)
    table = fap_table()
    weights = np.zeros((68, len(v0)))
    axes = np.zeros((68, 3))
    for f in table:
        if not f.is_translation or f.fdp not in fdp.points:
            continue
        p = v0[fdp.points[f.fdp]]
        dist = np.hypot(v0[:, 0] - p[0], v0[:, 1] - p[1])
        w = np.exp(-((dist / 0.2) ** 2))
        if f.number == 3:  # open_jaw: everything below the mouth
            w = np.clip((-0.5 - v0[:, 1]) / 0.3, 0, 1)
        weights[f.number - 1] = w
        axes[f.number - 1, f.axis_index] = f.sign
    eyes = {23: ("left_eye", "3.5", 1), 24: ("right_eye", "3.6", 1),
            25: ("left_eye", "3.5", 0), 26: ("right_eye", "3.6", 0)}

    def deform(values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, np.float64)
        out = v0[None] + np.einsum("kf,fv,fc->kvc", values * scale, weights, axes)
        for fap, (part, _key, axis) in eyes.items():
            ids = np.array(fdp.parts.get(part, []), np.int64)
            if not ids.size:
                continue
            c = v0[ids].mean(0) - np.array([0, 0, 0.1])
            for k in np.flatnonzero(values[:, fap - 1]):
                t = values[k, fap - 1] * 1e-5
                r = v0[ids] - c
                co, si = np.cos(t), np.sin(t)
                if axis == 1:
                    r = np.stack([co * r[:, 0] + si * r[:, 2], r[:, 1], -si * r[:, 0] + co * r[:, 2]], 1)
                else:
                    r = np.stack([r[:, 0], co * r[:, 1] - si * r[:, 2], si * r[:, 1] + co * r[:, 2]], 1)
                out[k, ids] += c + r - v0[ids]
        return out.astype(np.float32)

    return deform
