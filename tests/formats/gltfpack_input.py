"""The small animated scene that tests/formats/data/gltfpack_*.glb were made from with the real gltfpack.

    .venv/bin/python -m tests.formats.gltfpack_input /tmp/in.glb
    npx gltfpack@1.3.0 -i /tmp/in.glb -o tests/formats/data/gltfpack_cc.glb -cc -kn
    npx gltfpack@1.3.0 -i /tmp/in.glb -o tests/formats/data/gltfpack_vpf.glb -cc -kn -vpf
"""

from __future__ import annotations

import sys

import numpy as np

from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder


def scene() -> bytes:
    """A 12x12 curved sheet with normals, two morph targets, weights, rotation, translation and scale tracks."""
    n = 12
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    pos = np.stack([u, v, 0.3 * (1 - u * u)], -1).reshape(-1, 3).astype(np.float32) * 5
    normals = np.stack([0.6 * u / 5, 0 * v, np.ones_like(u)], -1).reshape(-1, 3)
    normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
    q = np.arange(n * n).reshape(n, n)
    a, b_, c, d = q[:-1, :-1], q[:-1, 1:], q[1:, 1:], q[1:, :-1]
    tris = np.concatenate([np.stack([a, b_, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    smile = np.zeros_like(pos)
    smile[:, 1] = 0.8 * np.exp(-((pos[:, 0] / 3) ** 2)) * (pos[:, 1] < 0)
    jaw = np.zeros_like(pos)
    jaw[:, 1] = -1.5 * np.clip(-pos[:, 1] / 5, 0, 1)
    b = GltfBuilder("facesvg tests")
    p = b.accessor(pos, minmax=True, target=ARRAY_BUFFER)
    nrm = b.accessor(normals, target=ARRAY_BUFFER)
    t1 = b.accessor(smile, minmax=True, target=ARRAY_BUFFER)
    t2 = b.accessor(jaw, minmax=True, target=ARRAY_BUFFER)
    ind = b.accessor(tris.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER)
    mat = b.add("materials", {"name": "Skin", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.6, 0.5, 1]}})
    mesh = b.add("meshes", {"name": "sheet", "weights": [0, 0], "extras": {"targetNames": ["smile", "jaw"]},
                            "primitives": [{"attributes": {"POSITION": p, "NORMAL": nrm}, "indices": ind,
                                            "material": mat, "targets": [{"POSITION": t1}, {"POSITION": t2}]}]})
    face = b.add("nodes", {"name": "face", "mesh": mesh, "translation": [0, 0, 1]})
    head = b.add("nodes", {"name": "head", "children": [face]})
    b.add("scenes", {"nodes": [head]})
    times = (np.arange(25) / 24).astype(np.float32)
    ang = np.radians(20) * np.sin(2 * np.pi * times)
    rot = np.stack([0 * ang, np.sin(ang / 2), 0 * ang, np.cos(ang / 2)], 1).astype(np.float32)
    w = np.stack([np.sin(np.pi * times) ** 2, 0.5 - 0.5 * np.cos(2 * np.pi * times)], 1).astype(np.float32)
    tr = np.stack([0.5 * times, 0 * times, 0 * times], 1).astype(np.float32)
    sc = np.stack([1 + 0.1 * times] * 3, 1).astype(np.float32)
    t = b.accessor(times[:, None], minmax=True)
    samplers = [{"input": t, "output": b.accessor(rot)}, {"input": t, "output": b.accessor(w.reshape(-1, 1))},
                {"input": t, "output": b.accessor(tr)}, {"input": t, "output": b.accessor(sc)}]
    channels = [{"sampler": 0, "target": {"node": head, "path": "rotation"}},
                {"sampler": 1, "target": {"node": face, "path": "weights"}},
                {"sampler": 2, "target": {"node": head, "path": "translation"}},
                {"sampler": 3, "target": {"node": face, "path": "scale"}}]
    b.add("animations", {"name": "wave", "samplers": samplers, "channels": channels})
    return b.glb()


if __name__ == "__main__":
    open(sys.argv[1], "wb").write(scene())
