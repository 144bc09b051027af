"""A small generated face with named morph targets, as an OBJ shape zip (neutral.obj + one OBJ per target).

A closed ellipsoid head (skin), two eyeballs (eye parts: the puppet's eye tables) and four ARKit-named targets:
jawOpen (the lower front drops and swings back: motion in depth, so its projection is not linear in the weight),
mouthSmileLeft, eyeBlinkLeft (the left eye squashes) and browInnerUp (a plain lift: linear).
"""

from __future__ import annotations

import io
import zipfile

import numpy as np


def sphere(n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit UV sphere: vertices (V, 3) and outward counter-clockwise triangles (F, 3)."""
    lat = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    ring = np.stack([np.sin(la) * np.sin(lo), np.cos(la), np.sin(la) * np.cos(lo)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]])
    south = len(verts) - 1
    faces = []
    idx = lambda i, j: 1 + i * n_lon + (j % n_lon)  # noqa: E731
    for j in range(n_lon):
        faces.append((0, idx(0, j), idx(0, j + 1)))
        faces.append((south, idx(n_lat - 2, j + 1), idx(n_lat - 2, j)))
    for i in range(n_lat - 2):
        for j in range(n_lon):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)
            faces += [(a, c, b), (b, c, d)]
    f = np.array(faces, np.int64)
    # orient outward: the normal of each triangle points away from the centre
    v = verts[f]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    flip = (n * v.mean(1)).sum(1) < 0
    f[flip] = f[flip][:, ::-1]
    return verts, f


def generated_face(n_lat: int = 28, n_lon: int = 40) -> tuple[np.ndarray, np.ndarray, list[int], dict[str, np.ndarray]]:
    """(base (V, 3), faces (F, 3), group of each face (0 skin, 1 left eye, 2 right eye), targets name -> (V, 3))."""
    hv, hf = sphere(n_lat, n_lon)
    hv = hv * np.array([0.8, 1.05, 0.85])
    ev, ef = sphere(8, 12)
    parts_v, parts_f, groups = [hv], [hf], [np.zeros(len(hf), int)]
    off = len(hv)
    eye_ids = []
    for g, x in ((1, 0.3), (2, -0.3)):
        centre = np.array([x, 0.25, 0.70])
        parts_v.append(ev * 0.14 + centre)
        parts_f.append(ef + off)
        groups.append(np.full(len(ef), g))
        eye_ids.append(np.arange(off, off + len(ev)))
        off += len(ev)
    base = np.concatenate(parts_v)
    faces = np.concatenate(parts_f)
    group = np.concatenate(groups)
    x, y, z = base[: len(hv)].T
    front = np.clip(z / 0.85, 0, 1)
    targets = {}
    jaw = np.zeros_like(base)
    low = np.clip((-0.05 - y) / 0.5, 0, 1) * front ** 2
    jaw[: len(hv), 1] = -0.35 * low
    jaw[: len(hv), 2] = -0.25 * low
    targets["jawOpen"] = jaw
    smile = np.zeros_like(base)
    near = np.exp(-((x - 0.3) ** 2 + (y + 0.35) ** 2) / 0.02) * front
    smile[: len(hv), 0] = 0.08 * near
    smile[: len(hv), 1] = 0.10 * near
    targets["mouthSmileLeft"] = smile
    blink = np.zeros_like(base)
    ids = eye_ids[0]
    centre = base[ids].mean(0)
    blink[ids, 1] = -(base[ids, 1] - centre[1]) * 0.8
    targets["eyeBlinkLeft"] = blink
    brow = np.zeros_like(base)
    brow[: len(hv), 1] = 0.06 * np.exp(-(x ** 2 + (y - 0.5) ** 2) / 0.03) * front
    targets["browInnerUp"] = brow
    return base, faces, group.tolist(), targets


def obj_text(verts: np.ndarray, faces: np.ndarray | None = None, group: list[int] | None = None) -> str:
    """An OBJ of vertices (and faces in groups skin, eye_left, eye_right)."""
    lines = [f"v {a:.6f} {b:.6f} {c:.6f}" for a, b, c in verts]
    if faces is not None:
        names = ("skin", "eye_left", "eye_right")
        current = None
        for f, g in zip(faces, group):
            if g != current:
                lines.append(f"usemtl {names[g]}")
                current = g
            lines.append(f"f {f[0] + 1} {f[1] + 1} {f[2] + 1}")
    return "\n".join(lines) + "\n"


def face_zip() -> bytes:
    """The generated face as an OBJ shape zip."""
    base, faces, group, targets = generated_face()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("neutral.obj", obj_text(base, faces, group))
        for name, d in targets.items():
            zf.writestr(f"{name}.obj", obj_text(base + d))
    return buf.getvalue()
