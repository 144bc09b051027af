"""Expression cloning: put a source face's animation onto a target face (FaceAnimation -> FaceAnimation).

Three methods behind one call: "example" (key-model pairs blended by cardinal RBF weights, seed 000),
"frames" (local reference frames per face region, same topology, seed 003) and "dense" (dense
correspondence by RBF morph and projection, book chapter 11). Frame 0 of the source is its neutral
face, frame 0 of the target the face to animate. Head pose is factored out of the source first (so
only expression is cloned) and re-applied to the result; eyeballs and teeth move as rigid pieces.
"""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation
from converter.cloning import dense, example_based, keyfile, local_frames, rigid
from converter.errors import InputError

METHODS = ("example", "frames", "dense")


def clone(source: FaceAnimation, target: FaceAnimation, method: str = "dense", keys: str | None = None,
          correspondences: str | None = None) -> FaceAnimation:
    """The source animation performed by the target face (target topology, parts and colours; source timing)."""
    if method not in METHODS:
        raise InputError(f"unknown cloning method {method!r}; choose one of {', '.join(METHODS)}.")
    if method == "frames" and source.n_vertices != target.n_vertices:
        raise InputError(f"local-frame cloning needs the same mesh topology, but the source has {source.n_vertices} "
                         f"vertices and the target {target.n_vertices}; use --method dense or example.")
    if method == "frames" and not np.array_equal(source.faces, target.faces):
        raise InputError("local-frame cloning needs the same mesh topology, but the triangles differ; "
                         "use --method dense or example.")
    if method == "example" and not keys:
        raise InputError("example-based cloning needs key-model pairs; give --keys pairs.zip.")
    head, pose, pivots, scale = factor_pose(source, target)
    if method == "dense":
        out = dense.clone(source.with_frames(head), target, head, correspondences)
    elif method == "frames":
        out = local_frames.clone(source.with_frames(head), target, correspondences)
    else:
        pairs = keyfile.read(keys, head[0], target.frames[0])
        out = example_based.ExampleCloner.fit(pairs).apply(head)
    out = rigid.apply_pose(out, pose, pivots[0], pivots[1], scale)
    return FaceAnimation(out.astype(np.float32), target.faces, target.part_ids, target.parts, source.fps,
                         f"{source.name}_on_{target.name}", target.vertex_colors, target.uvs, target.texture,
                         {"cloned_from": source.name, "clone_method": method})


def factor_pose(source: FaceAnimation, target: FaceAnimation):
    """(source frames without head pose, pose, (source pivot, target pivot), size ratio target/source)."""
    s_soft, t_soft = soft_vertices(source), soft_vertices(target)
    s0 = source.frames[0][s_soft].astype(np.float64)
    t0 = target.frames[0][t_soft].astype(np.float64)
    s_size = float(np.sqrt(((s0 - s0.mean(0)) ** 2).sum(1).mean()))
    t_size = float(np.sqrt(((t0 - t0.mean(0)) ** 2).sum(1).mean()))
    if s_size <= 0 or t_size <= 0:
        raise InputError("a face has all its vertices at one point; give a real mesh.")
    pose = rigid.estimate_pose(source.frames, s_soft, s_size)
    head = rigid.remove_pose(source.frames, pose)
    return head, pose, (s0.mean(0), t0.mean(0)), t_size / s_size


def soft_vertices(anim: FaceAnimation) -> np.ndarray:
    """Ids of the vertices of deformable parts (all used vertices when every part is rigid)."""
    ids = np.unique(rigid.soft_faces(anim))
    return ids if len(ids) else np.unique(anim.faces)
