"""Make samples/face.glb and samples/face_gltfpack.glb from the ICT FaceKit head (MIT).

    .venv/bin/python samples/make_sample.py [ICT_FACEKIT_FOLDER]   (default ../shared/data/ict_facekit)

The face region of the neutral ICT head (skin, mouth interior, teeth; each eye's sclera and iris as its own
node) simplified with meshoptimizer to about 3,000 triangles, vertex positions kept in ICT units (cm) and
coordinates; 9 expression shapes as morph targets; a 4 s, 30 fps sequence (smile, jaw open, blinks, brow
raise) with a little head rotation on the head node and STEP eye rotations on the eye nodes. Frame 0 is the
neutral rest pose. face_gltfpack.glb is the same asset the way gltfpack writes it: positions and morph
deltas quantized to integers (KHR_mesh_quantization, dequantized by the mesh nodes' scale and offset),
rotations with the QUATERNION filter, every buffer view EXT_meshopt_compression-encoded. Deterministic.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from converter.animation import DEFAULT_PART_COLORS
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder, encode_filter
from converter.formats.ictfacekit import IctHead, load_ict_head
from samples.ict_region import face_region, sphere_center

EXPRESSIONS = ("mouthSmile_L", "mouthSmile_R", "jawOpen", "eyeBlink_L", "eyeBlink_R",
               "browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R")
FPS = 30
N_FRAMES = 121  # 0 .. 4 s
TRIANGLES = 3000
HEAD_PIVOT = np.array([0.0, -6.0, 0.0])  # about where the neck turns the head, in ICT cm
MATERIAL_NAMES = {"skin": "Skin", "mouth": "MouthInterior", "teeth": "Teeth", "eye": "EyeSclera",
                  "iris": "Iris", "lashes": "Eyelashes"}
QUANT_BITS = 14  # position bits, as gltfpack's default


def envelope(t: np.ndarray, t0: float, t1: float, t2: float, t3: float, peak: float) -> np.ndarray:
    """0 before t0, smooth rise to peak by t1, hold, smooth fall to 0 by t3."""
    def smooth(x):
        x = np.clip(x, 0.0, 1.0)
        return x * x * (3 - 2 * x)
    return peak * smooth((t - t0) / (t1 - t0)) * (1 - smooth((t - t2) / (t3 - t2)))


def weight_curves(t: np.ndarray) -> np.ndarray:
    """(T, 9) expression weights over time t (s): smile, jaw open, two blinks, brow raise."""
    blink = envelope(t, 1.0, 1.1, 1.15, 1.3, 1.0) + envelope(t, 3.3, 3.4, 3.45, 3.6, 1.0)
    brow = envelope(t, 2.6, 3.0, 3.5, 3.9, 1.0)
    return np.stack([
        envelope(t, 0.2, 0.7, 1.3, 1.8, 0.9), envelope(t, 0.25, 0.75, 1.3, 1.8, 0.8),
        envelope(t, 1.6, 2.1, 2.4, 2.9, 0.7), blink, blink, 0.9 * brow, 0.9 * brow, 0.7 * brow, 0.7 * brow,
    ], axis=1)


def quat(yaw_deg: np.ndarray, pitch_deg: np.ndarray, roll_deg: np.ndarray | float = 0.0) -> np.ndarray:
    """(N, 4) x, y, z, w quaternions of yaw (about y) * pitch (about x) * roll (about z)."""
    y, p, r = (np.radians(np.broadcast_to(a, np.shape(yaw_deg))) / 2 for a in (yaw_deg, pitch_deg, roll_deg))
    qy = np.stack([0 * y, np.sin(y), 0 * y, np.cos(y)], 1)
    qx = np.stack([np.sin(p), 0 * p, 0 * p, np.cos(p)], 1)
    qz = np.stack([0 * r, 0 * r, np.sin(r), np.cos(r)], 1)
    return qmul(qmul(qy, qx), qz)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (N, 4) x, y, z, w quaternions."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], 1)


HEAD_KEYS = (np.arange(0, N_FRAMES, 15),  # frame, yaw, pitch, roll (degrees); LINEAR (slerp)
             np.array([0, 4, 8, 5, -2, -6, -3, 2, 0.0]), np.array([0, -2, -3, 0, 3, 4, 2, 0, 0.0]),
             np.array([0, 1, 2, 1, 0, -1, -1, 0, 0.0]))
EYE_KEYS = (np.array([0, 18, 45, 70, 95, 110]),  # frame, yaw, pitch; STEP (saccades)
            np.array([0, 10, -8, 0, 5, 0.0]), np.array([0, 0, 2, 8, -3, 0.0]))


def build(head: IctHead, quantized: bool) -> bytes:
    """The sample asset as .glb bytes (plain floats + sparse targets, or gltfpack-style)."""
    pieces = face_region(head, TRIANGLES)
    deltas = {name: head.delta(name).astype(np.float32) for name in EXPRESSIONS}
    b = GltfBuilder("facesvg samples/make_sample.py")
    meshopt = "ATTRIBUTES" if quantized else None
    if quantized:
        b.use_extension("KHR_mesh_quantization")
    materials = {}
    for part in dict.fromkeys(p.part for p in pieces):
        rgb = list(DEFAULT_PART_COLORS[part])
        materials[part] = b.add("materials", {"name": MATERIAL_NAMES[part], "pbrMetallicRoughness": {
            "baseColorFactor": rgb + [1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}})

    centers = {n: sphere_center(head.vertices[np.concatenate([p.ids for p in pieces if p.node == n])])
               for n in ("eye_left", "eye_right")}
    mesh_nodes = {}
    for node_name in ("face", "eye_left", "eye_right"):
        group = [p for p in pieces if p.node == node_name]
        morph = node_name == "face"
        allv = head.vertices[np.concatenate([p.ids for p in group])].astype(np.float64)
        lo, step = allv.min(0), float((allv.max(0) - allv.min(0)).max()) / ((1 << QUANT_BITS) - 1)
        prims = []
        for p in group:
            v = head.vertices[p.ids].astype(np.float32)
            if quantized:
                q = np.zeros((len(v), 4), np.uint16)
                q[:, :3] = np.round((v - lo) / step)
                pos = b.accessor(q, "VEC3", minmax=True, target=ARRAY_BUFFER, meshopt=meshopt)
            else:
                pos = b.accessor(v, minmax=True, target=ARRAY_BUFFER)
            ind = b.accessor(p.faces.reshape(-1).astype(np.uint16 if len(v) < 65536 else np.uint32),
                             target=ELEMENT_ARRAY_BUFFER, meshopt="TRIANGLES" if quantized else None)
            prim = {"attributes": {"POSITION": pos}, "indices": ind, "material": materials[p.part]}
            if morph:
                prim["targets"] = [{"POSITION": target_accessor(b, deltas[e][p.ids], quantized, step)}
                                   for e in EXPRESSIONS]
            prims.append(prim)
        mesh = {"name": node_name, "primitives": prims}
        if morph:
            mesh["weights"] = [0.0] * len(EXPRESSIONS)
            mesh["extras"] = {"targetNames": list(EXPRESSIONS)}
        mesh_index = b.add("meshes", mesh)
        offset = -HEAD_PIVOT if node_name == "face" else -centers[node_name]
        node = {"name": f"{node_name}_mesh" if node_name != "face" else "face", "mesh": mesh_index}
        if quantized:
            node["translation"] = [float(x) for x in offset + lo]
            node["scale"] = [step] * 3
        else:
            node["translation"] = [float(x) for x in offset]
        mesh_nodes[node_name] = b.add("nodes", node)

    eye_nodes = {n: b.add("nodes", {"name": n, "translation": [float(x) for x in centers[n] - HEAD_PIVOT],
                                    "children": [mesh_nodes[n]]}) for n in ("eye_left", "eye_right")}
    head_node = b.add("nodes", {"name": "head", "translation": [float(x) for x in HEAD_PIVOT],
                                "children": [mesh_nodes["face"], eye_nodes["eye_left"], eye_nodes["eye_right"]]})
    b.add("scenes", {"name": "face", "nodes": [head_node]})
    b.doc["scene"] = 0

    frames = np.arange(N_FRAMES)
    w = weight_curves(frames / FPS).astype(np.float32)
    samplers, channels = [], []

    def track(node: int, path: str, key_frames: np.ndarray, values: np.ndarray, interp: str) -> None:
        times = b.accessor((key_frames / FPS).astype(np.float32)[:, None], minmax=True, meshopt=meshopt)
        if quantized and path == "rotation":
            out = b.accessor(encode_filter("quat", values, 12), "VEC4", normalized=True, meshopt=meshopt,
                             filter="QUATERNION")
        else:
            out = b.accessor(values.astype(np.float32), "SCALAR" if path == "weights" else None, meshopt=meshopt)
        samplers.append({"input": times, "output": out, "interpolation": interp})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})

    track(mesh_nodes["face"], "weights", frames, w, "LINEAR")
    track(head_node, "rotation", HEAD_KEYS[0], quat(*HEAD_KEYS[1:]), "LINEAR")
    for n in ("eye_left", "eye_right"):
        track(eye_nodes[n], "rotation", EYE_KEYS[0], quat(*EYE_KEYS[1:]), "STEP")
    b.add("animations", {"name": "smile_jaw_blink_brow", "samplers": samplers, "channels": channels})
    return b.glb()


def target_accessor(b: GltfBuilder, delta: np.ndarray, quantized: bool, step: float) -> int:
    """A morph target's POSITION deltas: sparse floats, or dense quantized int16 for the gltfpack twin."""
    if quantized:
        q = np.zeros((len(delta), 4), np.int16)
        q[:, :3] = np.round(delta / step)
        return b.accessor(q, "VEC3", minmax=True, target=ARRAY_BUFFER, meshopt="ATTRIBUTES")
    moved = np.flatnonzero(np.abs(delta).max(1) > 1e-5)
    if len(moved) == 0:
        return b.add("accessors", {"componentType": 5126, "count": len(delta), "type": "VEC3",
                                   "min": [0.0] * 3, "max": [0.0] * 3})
    index_type = np.uint16 if len(delta) < 65536 else np.uint32
    return b.sparse_accessor(len(delta), moved.astype(index_type), delta[moved].astype(np.float32), minmax=True)


def main(argv: list[str]) -> int:
    folder = Path(argv[0]) if argv else ROOT.parent / "shared" / "data" / "ict_facekit"
    head = load_ict_head(folder)
    for quantized, name in ((False, "face.glb"), (True, "face_gltfpack.glb")):
        data = build(head, quantized)
        (ROOT / "samples" / name).write_bytes(data)
        print(f"samples/{name}: {len(data)} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
