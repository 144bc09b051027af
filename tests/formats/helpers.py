"""Small glTF scenes for the loader tests, built with GltfBuilder."""

from __future__ import annotations

import numpy as np

from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)


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
