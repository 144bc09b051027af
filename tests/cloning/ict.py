"""ICT FaceKit test subjects for cloning: the head as a FaceAnimation, a simplified copy, blendshape animations."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import meshoptimizer
import numpy as np

from converter.animation import FaceAnimation
from converter.formats.ictfacekit import load_ict_head

ICT = Path(__file__).resolve().parents[3] / "shared" / "data" / "ict_facekit"
KEEP_PARTS = ("skin", "eye", "iris")  # the face surface and the eyeballs (rigid parts)


@lru_cache(maxsize=2)
def head(folder: str = str(ICT)):
    """(neutral (V,3), faces, part_ids, parts, deltas (27,V,3), names) with only KEEP_PARTS, vertices compacted."""
    h = load_ict_head(folder)
    keep = np.isin(np.array([p.name for p in h.parts])[h.part_ids], KEEP_PARTS)
    faces = h.faces[keep]
    used = np.unique(faces)
    remap = np.full(len(h.vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    names = h.expression_names()
    deltas = np.stack([h.delta(n)[used] for n in names]).astype(np.float32)
    return h.vertices[used], remap[faces].astype(np.int32), h.part_ids[keep], h.parts, deltas, tuple(names)


def weights(n_frames: int, n_keys: int, seed: int = 0, active: int = 3) -> np.ndarray:
    """Smooth random blendshape weights (T, K) in [0, 1], a few keys active at a time."""
    rng = np.random.default_rng(seed)
    w = np.zeros((n_frames, n_keys))
    t = np.arange(n_frames)
    for _ in range(active * max(1, n_frames // 20)):
        k = rng.integers(n_keys)
        c, s, a = rng.uniform(0, n_frames), rng.uniform(3, 10), rng.uniform(0.3, 1.0)
        w[:, k] += a * np.exp(-0.5 * ((t - c) / s) ** 2)
    w[0] = 0.0  # frame 0 is the neutral face the cloning methods measure motion from
    return np.clip(w, 0, 1)


def animation(w: np.ndarray, base, faces, part_ids, parts, deltas, name: str = "ict") -> FaceAnimation:
    """Blendshape animation: base + w @ deltas."""
    frames = base[None] + np.einsum("tk,kvc->tvc", w, deltas)
    return FaceAnimation(frames.astype(np.float32), faces, part_ids, parts, 30.0, name)


def simplified(base, faces, part_ids, target_vertices: int = 1200):
    """A meshoptimizer-simplified copy: (kept vertex ids into base, faces over them, part ids)."""
    out_f, out_p = [], []
    skin = part_ids == 0
    budget = {True: target_vertices - 160, False: 160}
    for is_skin in (True, False):
        f = faces[skin == is_skin]
        p = part_ids[skin == is_skin]
        if not len(f):
            continue
        n_v = len(np.unique(f))
        goal = int(len(f) * budget[is_skin] / n_v) * 3
        dest = np.zeros(f.size, np.uint32)
        n = meshoptimizer.simplify(dest, f.astype(np.uint32).ravel(), base.astype(np.float32),
                                   target_index_count=goal, target_error=0.05)
        sf = dest[:n].reshape(-1, 3).astype(np.int64)
        # Part of each kept triangle: the part of the original triangle sharing its first vertex.
        part_of_vertex = np.zeros(len(base), np.int32)
        part_of_vertex[f.ravel()] = np.repeat(p, 3)
        out_f.append(sf)
        out_p.append(part_of_vertex[sf[:, 0]])
    f = np.concatenate(out_f)
    kept = np.unique(f)
    remap = np.full(len(base), -1, np.int64)
    remap[kept] = np.arange(len(kept))
    return kept, remap[f].astype(np.int32), np.concatenate(out_p).astype(np.int32)
