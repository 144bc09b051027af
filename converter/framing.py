"""What the camera frames: a part or glTF node the user names, or by default the head of a full-body avatar."""

from __future__ import annotations

import re
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError

HEAD_NAME = re.compile(r"head|face", re.I)
# A few ARKit blendshape names (any naming style once lower-cased without separators): a face's morph targets.
ARKIT_TARGETS = frozenset({"jawopen", "eyeblinkleft", "eyeblinkright", "eyeblinkl", "eyeblinkr", "mouthsmileleft",
                           "mouthsmileright", "browinnerup", "mouthfunnel", "mouthpucker", "jawforward"})
MANY_TARGETS = 20  # a mesh with this many morph targets is taken for the face
FULL_BODY_RATIO = 0.4  # the head is framed only when its height is below this share of the whole scene's


class Framing(NamedTuple):
    """The vertices the camera fits (None: all), degrees of yaw added to the user's, and notes for the Report."""

    vertices: np.ndarray | None
    yaw: float
    notes: tuple[str, ...]


def candidates(anim: FaceAnimation) -> list[str]:
    """The names --frame-on accepts for this animation: its parts, then its glTF nodes and meshes."""
    names = list(dict.fromkeys(p.name for p in anim.parts))  # several primitives can share a part name
    for node, _, mesh, _ in anim.extras.get("node_tree", ()):
        for n in (node, mesh):
            if n and n not in names:
                names.append(n)
    return names


def decide(anim: FaceAnimation, frame_on: str | None = None) -> FaceAnimation:
    """The animation with its Framing fixed in extras, so stages that drop vertices (simplify) keep the choice."""
    framed = resolve(anim, frame_on)
    return replace(anim, extras={**anim.extras, "framing": (frame_on, framed.notes), "framed_vertices": (
        np.ones(anim.n_vertices, bool) if framed.vertices is None else framed.vertices)})


def resolve(anim: FaceAnimation, frame_on: str | None = None) -> Framing:
    """The Framing for an animation: frame_on's vertices, else the head of a full-body avatar, else everything."""
    decided, mask = anim.extras.get("framing"), anim.extras.get("framed_vertices")
    if decided is not None and decided[0] == frame_on and mask is not None and len(mask) == anim.n_vertices:
        yaw = 180.0 if anim.extras.get("vrm") == "0.x" else 0.0
        return Framing(None if mask.all() or not mask.any() else mask, yaw, decided[1])
    yaw, notes = 0.0, []
    if anim.extras.get("vrm") == "0.x":  # VRM 0.x avatars face -Z; VRM 1.0 ones face +Z like glTF
        yaw = 180.0
        notes.append("VRM 0.x avatar: the camera is turned to its front (-Z)")
    if frame_on is not None:
        mask = _named(anim, frame_on)
        if mask is None or not mask.any():
            raise InputError(f"--frame-on {frame_on!r} names no part or node of this file; choose one of "
                             f"{', '.join(candidates(anim)) or 'its parts'}.")
        notes.append(f"framed {frame_on!r}")
        return Framing(mask, yaw, tuple(notes))
    mask, label = _head(anim)
    if mask is not None:
        notes.append(f"framed the head ({label}); --frame-on NAME frames another part or node")
    return Framing(mask, yaw, tuple(notes))


def _node_vertices(anim: FaceAnimation, key: str = "node_of_vertex") -> tuple[tuple, np.ndarray | None]:
    """The node tree and each vertex's node (or strongest joint), when the loader recorded them for these vertices."""
    tree = anim.extras.get("node_tree", ())
    of_vertex = anim.extras.get(key)
    if of_vertex is None or len(of_vertex) != anim.n_vertices:  # e.g. a stage replaced the mesh
        return (), None
    return tree, np.asarray(of_vertex)


def _subtree(tree: tuple, roots: np.ndarray) -> np.ndarray:
    """Bool per node: the node is one of roots or below one (the tree lists parents first)."""
    inside = roots.copy()
    for i, (_, parent, _, _) in enumerate(tree):
        if parent >= 0 and inside[parent]:
            inside[i] = True
    return inside


def _named(anim: FaceAnimation, name: str) -> np.ndarray | None:
    """Bool (V,) of the part, node (with its children) or mesh called name (case-insensitive), or None."""
    key = name.casefold()
    parts = [i for i, p in enumerate(anim.parts) if p.name.casefold() == key]
    if parts:
        mask = np.zeros(anim.n_vertices, bool)
        mask[anim.faces[np.isin(anim.part_ids, parts)].reshape(-1)] = True
        return mask
    tree, of_vertex = _node_vertices(anim)
    if of_vertex is None:
        return None
    roots = np.array([node.casefold() == key or mesh.casefold() == key for node, _, mesh, _ in tree], bool)
    if not roots.any():
        return None
    inside = _subtree(tree, roots)
    mask = inside[of_vertex]
    _, joint_of_vertex = _node_vertices(anim, "joint_of_vertex")
    if joint_of_vertex is not None:  # a joint (e.g. a skeleton's Head bone): the vertices it or its children move most
        mask |= np.append(inside, False)[joint_of_vertex]
    return mask


def _is_face_mesh(targets: tuple[str, ...]) -> bool:
    normalised = {re.sub(r"[\W_]", "", t).casefold() for t in targets}
    return len(normalised & ARKIT_TARGETS) >= 2 or len(targets) >= MANY_TARGETS


def _head(anim: FaceAnimation) -> tuple[np.ndarray | None, str]:
    """The head's vertices and a label when the file is a full-body avatar with a recognisable head, else None.

    Head candidates are nodes or meshes named like head/face (with their children) and meshes carrying face morph
    targets; together they must be short (under FULL_BODY_RATIO of the scene's height) and at its top, so a
    face-only file (whose teeth may carry morph targets too) keeps being framed whole.
    """
    tree, of_vertex = _node_vertices(anim)
    if of_vertex is None or len(tree) < 2:
        return None, ""
    ys = anim.frames[..., 1]
    top, height = float(ys.max()), float(ys.max() - ys.min())
    if height <= 0:
        return None, ""
    named = np.array([bool(HEAD_NAME.search(node) or HEAD_NAME.search(mesh)) for node, _, mesh, _ in tree], bool)
    by_name = _subtree(tree, named)
    chosen = [i for i, (_, _, _, targets) in enumerate(tree) if by_name[i] or _is_face_mesh(targets)]
    mask = np.isin(of_vertex, chosen)
    if not mask.any() or mask.all():
        return None, ""
    head_ys = ys[:, mask]
    if float(head_ys.max() - head_ys.min()) >= FULL_BODY_RATIO * height or float(head_ys.max()) < top - 0.15 * height:
        return None, ""
    shown = [i for i in chosen if named[i]] or chosen
    return mask, ", ".join(f"node {tree[i][0]!r}" for i in shown)
