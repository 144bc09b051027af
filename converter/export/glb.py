"""Write a FaceAnimation as a .glb: one mesh, a primitive per part, one morph target per frame, STEP weights."""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.lighting import srgb_to_linear


def write_glb(anim: FaceAnimation) -> bytes:
    """The animation as deterministic GLB bytes that converter.formats.load reads back frame for frame.

    Frame 0 is the base mesh; frame k > 0 is morph target k-1 with weight 1 while frame k shows (STEP sampler),
    so any glTF viewer plays it and the loader recovers every frame exactly.
    """
    b = GltfBuilder()
    base = np.ascontiguousarray(anim.frames[0], np.float32)
    pos = b.accessor(base, minmax=True, target=ARRAY_BUFFER)
    deltas = anim.frames[1:] - anim.frames[:1]
    targets = [{"POSITION": b.accessor(np.ascontiguousarray(d, np.float32), minmax=True, target=ARRAY_BUFFER)}
               for d in deltas]
    attributes = {"POSITION": pos}
    if anim.vertex_colors is not None:
        # glTF colours are linear; ours are display values (converter/animation.py).
        attributes["COLOR_0"] = b.accessor(srgb_to_linear(anim.vertex_colors), target=ARRAY_BUFFER)
    primitives = []
    for pid, part in enumerate(anim.parts):
        tris = anim.faces[anim.part_ids == pid]
        if not len(tris):
            continue
        mat = b.add("materials", {"name": part.name, "pbrMetallicRoughness": {
            "baseColorFactor": [float(c) for c in srgb_to_linear(part.color)] + [1.0], "metallicFactor": 0.0}})
        idx = b.accessor(np.ascontiguousarray(tris.reshape(-1), np.uint32), target=ELEMENT_ARRAY_BUFFER)
        prim = {"attributes": attributes, "indices": idx, "material": mat, "mode": 4}
        if targets:
            prim["targets"] = targets
        primitives.append(prim)
    mesh = {"name": anim.name, "primitives": primitives}
    if targets:
        mesh["weights"] = [0.0] * len(targets)
    b.add("nodes", {"name": anim.name, "mesh": b.add("meshes", mesh)})
    b.add("scenes", {"nodes": [0]})
    b.doc["scene"] = 0
    if targets:
        t = anim.n_frames
        times = (np.arange(t, dtype=np.float32) / np.float32(anim.fps)).astype(np.float32)
        weights = np.zeros((t, t - 1), np.float32)
        weights[np.arange(1, t), np.arange(t - 1)] = 1.0
        inp = b.accessor(times, minmax=True)
        out = b.accessor(weights.reshape(-1))
        b.add("animations", {"name": "frames", "samplers": [{"input": inp, "output": out, "interpolation": "STEP"}],
                             "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]})
    return b.glb()
