"""Small glTF scenes for the loader tests, built with GltfBuilder."""

from __future__ import annotations

import numpy as np

from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)


def srgb(linear) -> np.ndarray:
    """The sRGB encoding of linear values, written from the spec (IEC 61966-2-1) for the tests' expectations."""
    x = np.asarray(linear, np.float64)
    return np.where(x > 0.0031308, 1.055 * np.abs(x) ** (1 / 2.4) - 0.055, 12.92 * x)


def linear(encoded) -> np.ndarray:
    """The inverse: sRGB-encoded values to linear light."""
    x = np.asarray(encoded, np.float64)
    return np.where(x > 0.04045, ((x + 0.055) / 1.055) ** 2.4, x / 12.92)


def triangle_scene(b: GltfBuilder | None = None, positions: np.ndarray = TRI, material: dict | None = None,
                   node: dict | None = None, mesh_name: str = "face",
                   extra_prim: dict | None = None) -> tuple[GltfBuilder, int]:
    """A one-triangle mesh on one node (returned), in scene 0."""
    b = b or GltfBuilder("tests")
    pos = b.accessor(np.asarray(positions, np.float32), minmax=True, target=ARRAY_BUFFER)
    ind = b.accessor(np.arange(len(positions), dtype=np.uint16), target=ELEMENT_ARRAY_BUFFER)
    prim = {"attributes": {"POSITION": pos}, "indices": ind, **(extra_prim or {})}
    if material is not None:
        prim["material"] = b.add("materials", material)
    mesh = b.add("meshes", {"name": mesh_name, "primitives": [prim]})
    n = b.add("nodes", {"mesh": mesh, **(node or {})})
    b.add("scenes", {"nodes": [n]})
    return b, n


def add_track(b: GltfBuilder, node: int, path: str, times, values, interp: str = "LINEAR", anim: int = 0,
              name: str | None = None) -> None:
    """One animation channel in animation anim (created, with name, when missing)."""
    while len(b.doc.get("animations", [])) <= anim:
        b.add("animations", {"samplers": [], "channels": []})
    if name is not None:
        b.doc["animations"][anim]["name"] = name
    anim = b.doc["animations"][anim]
    t = b.accessor(np.asarray(times, np.float32)[:, None], minmax=True)
    v = np.asarray(values, np.float32)
    out = b.accessor(v.reshape(-1, 1) if path == "weights" else v, "SCALAR" if path == "weights" else None)
    anim["samplers"].append({"input": t, "output": out, "interpolation": interp})
    anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})


def skinned_triangle(joints=None, weights=None, n_joints: int = 1, inverse_bind: np.ndarray | None = None,
                     joints_dtype=np.uint8) -> tuple[GltfBuilder, int, list[int]]:
    """The triangle skinned to n_joints chained joint nodes (returned with the mesh node), all weight on joint 0."""
    b = GltfBuilder("tests")
    joints = np.zeros((3, 4), joints_dtype) if joints is None else np.asarray(joints, joints_dtype)
    weights = np.float32([[1, 0, 0, 0]] * 3) if weights is None else np.asarray(weights, np.float32)
    attrs = {"POSITION": b.accessor(TRI, minmax=True, target=ARRAY_BUFFER),
             "JOINTS_0": b.accessor(joints, target=ARRAY_BUFFER),
             "WEIGHTS_0": b.accessor(weights, target=ARRAY_BUFFER)}
    mesh = b.add("meshes", {"primitives": [{"attributes": attrs}]})
    joint_nodes = [b.add("nodes", {"name": f"joint{i}"}) for i in range(n_joints)]
    for parent, child in zip(joint_nodes, joint_nodes[1:]):
        b.doc["nodes"][parent]["children"] = [child]
    skin = {"joints": joint_nodes}
    if inverse_bind is not None:
        skin["inverseBindMatrices"] = b.accessor(np.ascontiguousarray(inverse_bind, np.float32).reshape(-1, 16),
                                                 "MAT4")
    node = b.add("nodes", {"name": "body", "mesh": mesh, "skin": b.add("skins", skin)})
    b.add("scenes", {"nodes": [node, joint_nodes[0]]})
    return b, node, joint_nodes
