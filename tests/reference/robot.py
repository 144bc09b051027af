"""A generated thin-limbed skinned robot (.glb): box torso and head, limbs and an antenna a few px wide at the
default size, eight joints and one rotation clip (the body turns, arms swing and bend, legs step).

Used by tests/reference/test_threejs.py: thin parts are mostly outline, where a seam stroke drawn outside the
silhouette shows (IoU against three.js). The limbs are 8-sided cylinders with shared vertices, the torso a box
with split (flat-shaded) vertices, as exporters write them, so outline edges are found both on shared and on
welded vertices. Units: y up, facing +z.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder

FPS = 30
DURATION = 2.0
ARM_RADIUS = 0.007  # ~3 px wide at 512 px (the figure is ~2.2 units tall)
LEG_RADIUS = 0.01
ANTENNA_RADIUS = 0.004
# joint: (parent, bind position); the limbs hang from them
JOINTS = {
    "root": (None, (0.0, 0.75, 0.0)),
    "neck": ("root", (0.0, 1.65, 0.0)),
    "shoulder_l": ("root", (0.33, 1.55, 0.0)),
    "elbow_l": ("shoulder_l", (0.33, 1.2, 0.0)),
    "shoulder_r": ("root", (-0.33, 1.55, 0.0)),
    "elbow_r": ("shoulder_r", (-0.33, 1.2, 0.0)),
    "hip_l": ("root", (0.15, 0.75, 0.0)),
    "hip_r": ("root", (-0.15, 0.75, 0.0)),
}
NAMES = list(JOINTS)


def _cylinder(radius: float, top: tuple[float, float, float], length: float, rings: int) -> trimesh.Trimesh:
    """An 8-sided cylinder along -y from top, with `rings` segments (shared vertices, capped)."""
    sections = 8
    ys = np.linspace(0.0, -length, rings + 1)
    ang = 2 * np.pi * np.arange(sections) / sections
    ring = np.stack([radius * np.cos(ang), np.zeros(sections), radius * np.sin(ang)], 1)
    verts = [ring + [0, y, 0] for y in ys]
    v = np.concatenate(verts + [[[0, 0, 0]], [[0, -length, 0]]]) + np.asarray(top)
    faces = []
    for r in range(rings):
        for s in range(sections):
            a, b = r * sections + s, r * sections + (s + 1) % sections
            c, d = a + sections, b + sections
            faces += [[a, b, c], [b, d, c]]
    top_c, bottom_c = len(v) - 2, len(v) - 1
    last = rings * sections
    for s in range(sections):
        faces.append([top_c, (s + 1) % sections, s])
        faces.append([bottom_c, last + s, last + (s + 1) % sections])
    mesh = trimesh.Trimesh(v, np.array(faces), process=False)
    mesh.fix_normals()  # outward winding
    return mesh


def _box(extents: tuple[float, float, float], centre: tuple[float, float, float]) -> trimesh.Trimesh:
    """A box with split vertices (every face its own 4 corners), as a flat-shaded export writes it."""
    box = trimesh.creation.box(extents)
    box.apply_translation(centre)
    tri = box.vertices[box.faces]  # (F, 3, 3) unshared
    return trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3), process=False)


def _weights(v: np.ndarray, joint: str, lower: str | None = None, split_y: float = 0.0) -> np.ndarray:
    """(V, 8) weights: all on joint, or blended onto lower below split_y (a 0.04 unit ramp)."""
    w = np.zeros((len(v), len(NAMES)), np.float32)
    if lower is None:
        w[:, NAMES.index(joint)] = 1
        return w
    t = np.clip((split_y + 0.02 - v[:, 1]) / 0.04, 0, 1)
    w[:, NAMES.index(joint)] = 1 - t
    w[:, NAMES.index(lower)] = t
    return w


def parts() -> list[tuple[str, trimesh.Trimesh, np.ndarray, tuple[float, float, float]]]:
    """(name, mesh, weights (V, 8), colour) of each part in the bind pose."""
    out = []
    torso = _box((0.6, 0.9, 0.3), (0.0, 1.2, 0.0))
    out.append(("torso", torso, _weights(torso.vertices, "root"), (0.55, 0.57, 0.6)))
    head = _box((0.3, 0.28, 0.28), (0.0, 1.82, 0.0))
    out.append(("head", head, _weights(head.vertices, "neck"), (0.7, 0.72, 0.75)))
    antenna = _cylinder(ANTENNA_RADIUS, (0.08, 2.2, 0.0), 0.25, 3)
    out.append(("antenna", antenna, _weights(antenna.vertices, "neck"), (0.85, 0.2, 0.2)))
    for side, x in (("l", 0.33), ("r", -0.33)):
        arm = _cylinder(ARM_RADIUS, (x, 1.55, 0.0), 0.7, 8)
        out.append((f"arm_{side}", arm, _weights(arm.vertices, f"shoulder_{side}", f"elbow_{side}", 1.2),
                    (0.2, 0.35, 0.8)))
    for side, x in (("l", 0.15), ("r", -0.15)):
        leg = _cylinder(LEG_RADIUS, (x, 0.75, 0.0), 0.75, 6)
        out.append((f"leg_{side}", leg, _weights(leg.vertices, f"hip_{side}"), (0.25, 0.3, 0.35)))
    return out


def _quats(times: np.ndarray, euler_deg: np.ndarray) -> np.ndarray:
    """(T, 4) xyzw quaternions of intrinsic XYZ angles (T, 3) in degrees."""
    return Rotation.from_euler("XYZ", euler_deg, degrees=True).as_quat().astype(np.float32)


def robot() -> bytes:
    """The robot .glb: one skinned mesh (a primitive per part), the clip 'walk_and_turn'."""
    b = GltfBuilder("facesvg tests/reference/robot.py")
    prims = []
    for name, mesh, w, colour in parts():
        material = b.add("materials", {"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": list(colour) + [1.0], "metallicFactor": 0.0}})
        top = np.argsort(-w, axis=1)[:, :4]
        attrs = {"POSITION": b.accessor(mesh.vertices.astype(np.float32), minmax=True, target=ARRAY_BUFFER),
                 "JOINTS_0": b.accessor(top.astype(np.uint8), target=ARRAY_BUFFER),
                 "WEIGHTS_0": b.accessor(np.take_along_axis(w, top, 1).astype(np.float32), target=ARRAY_BUFFER)}
        prims.append({"attributes": attrs, "material": material,
                      "indices": b.accessor(mesh.faces.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER)})
    mesh_index = b.add("meshes", {"name": "robot", "primitives": prims})
    nodes: dict[str, int] = {}
    for name in reversed(NAMES):  # children before parents
        parent, pos = JOINTS[name]
        offset = np.asarray(pos) - (np.asarray(JOINTS[parent][1]) if parent else 0.0)
        kids = [nodes[c] for c in NAMES if JOINTS[c][0] == name]
        node = {"name": name, "translation": [float(x) for x in offset]}
        if kids:
            node["children"] = kids
        nodes[name] = b.add("nodes", node)
    ibm = np.stack([np.eye(4)] * len(NAMES))
    ibm[:, :3, 3] = -np.array([JOINTS[n][1] for n in NAMES])
    skin = b.add("skins", {"joints": [nodes[n] for n in NAMES], "skeleton": nodes["root"],
                           "inverseBindMatrices": b.accessor(ibm.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32),
                                                             "MAT4")})
    body = b.add("nodes", {"name": "robot", "mesh": mesh_index, "skin": skin})
    b.add("scenes", {"nodes": [nodes["root"], body]})

    times = (np.arange(int(DURATION * FPS) + 1) / FPS).astype(np.float32)
    s = np.sin(2 * np.pi * times / DURATION)
    c = np.cos(2 * np.pi * times / DURATION)
    zero = 0 * times
    tracks = {
        "root": np.stack([zero, 35 * s, 5 * c], 1),  # the body turns +-35 degrees and rocks
        "neck": np.stack([10 * c, -20 * s, zero], 1),
        "shoulder_l": np.stack([40 * s, zero, 25 + 15 * c], 1),  # swings forward/back and out
        "elbow_l": np.stack([-30 - 30 * s, zero, zero], 1),
        "shoulder_r": np.stack([-40 * s, zero, -25 - 15 * s], 1),
        "elbow_r": np.stack([-30 + 30 * s, zero, zero], 1),
        "hip_l": np.stack([25 * s, zero, 5 * c], 1),
        "hip_r": np.stack([-25 * s, zero, -5 * c], 1),
    }
    t = b.accessor(times[:, None], minmax=True)
    samplers, channels = [], []
    for name, euler in tracks.items():
        samplers.append({"input": t, "output": b.accessor(_quats(times, euler)), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": nodes[name], "path": "rotation"}})
    b.add("animations", {"name": "walk_and_turn", "samplers": samplers, "channels": channels})
    return b.glb()
