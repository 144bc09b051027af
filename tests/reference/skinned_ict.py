"""A skinned face glTF built from the ICT FaceKit head: root -> neck -> head -> jaw joints, morph targets, a 2 s take.

Used by tests/reference/test_skinned_ict.py and bench/bench_reference.py (issue 15: skinning on a face, checked
against three.js). Units are the ICT head's (cm, y up, facing +z). Weights are worked out from the neutral shape:
neck/head by height with a smooth blend zone across the neck, the jaw on the chin and lower lip (below the mouth
corners, in front of the jaw pivot, above the throat), each edge a smoothstep ramp so vertices blend.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from converter.animation import DEFAULT_PART_COLORS
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.formats.ictfacekit import IctHead
from samples.ict_region import face_region

TRIANGLES = 4000
EXPRESSIONS = ("eyeBlink_L", "mouthSmile_L", "browInnerUp_R")
FPS = 30
DURATION = 2.0
ROOT = np.array([0.0, -20.0, 0.0])  # the root joint sits under the neck, so no inverse bind matrix is identity
NECK = np.array([0.0, -14.0, -1.0])
HEAD = np.array([0.0, -8.0, 0.0])
JAW = np.array([0.0, -1.5, 2.0])  # near the ear line, behind the cheek
JOINT_NAMES = ("root", "neck", "head", "jaw")


def smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """0 at lo, 1 at hi, smooth in between (lo > hi ramps the other way)."""
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def skin_weights(v: np.ndarray) -> np.ndarray:
    """(V, 4) weights on (root, neck, head, jaw) for neutral positions v (V, 3); each row sums to 1."""
    head = smoothstep(v[:, 1], -12.0, -7.5)  # the neck blends into the head between these heights
    jaw = (smoothstep(v[:, 1], -3.3, -4.5)  # below the mouth corners (y -3.5): the lower lip blends
           * smoothstep(v[:, 2], 3.0, 6.5)  # in front of the jaw pivot
           * smoothstep(v[:, 1], -10.5, -8.0))  # and not the throat below the chin
    root = 1 - smoothstep(v[:, 1], -16.5, -15.0)  # the cut edge of the neck stays put
    rest = 1 - jaw
    w = np.stack([root * rest, (1 - root) * (1 - head) * rest, (1 - root) * head * rest, jaw], axis=1)
    return w / w.sum(1, keepdims=True)


def unorm8(w: np.ndarray) -> np.ndarray:
    """Weights as normalised UNSIGNED_BYTE whose rows sum to exactly 255 (the largest takes the rounding)."""
    q = np.round(w * 255).astype(np.int64)
    top = np.argmax(w, axis=1)
    q[np.arange(len(q)), top] += 255 - q.sum(1)
    return q.astype(np.uint8)


def _quat_keys(times: np.ndarray, x_deg: np.ndarray, y_deg: np.ndarray) -> np.ndarray:
    """(T, 4) xyzw quaternions: yaw about y, then pitch about x (intrinsic)."""
    return Rotation.from_euler("YX", np.stack([y_deg, x_deg], 1), degrees=True).as_quat().astype(np.float32)


def skinned_face(head: IctHead, byte_weights: bool = False, triangles: int = TRIANGLES) -> bytes:
    """The skinned, morphing ICT face as .glb bytes; byte_weights stores WEIGHTS_0 as normalised UNSIGNED_BYTE."""
    pieces = face_region(head, triangles)
    deltas = {name: head.delta(name).astype(np.float32) for name in EXPRESSIONS}
    b = GltfBuilder("facesvg tests/reference/skinned_ict.py")
    prims = []
    for p in pieces:
        v = head.vertices[p.ids].astype(np.float32)
        w = skin_weights(v.astype(np.float64))
        weights = (b.accessor(unorm8(w), normalized=True, target=ARRAY_BUFFER) if byte_weights
                   else b.accessor(w.astype(np.float32), target=ARRAY_BUFFER))
        material = b.add("materials", {"name": p.part, "pbrMetallicRoughness": {
            "baseColorFactor": list(DEFAULT_PART_COLORS[p.part]) + [1.0], "metallicFactor": 0.0}})
        attrs = {"POSITION": b.accessor(v, minmax=True, target=ARRAY_BUFFER),
                 "JOINTS_0": b.accessor(np.tile(np.uint8([0, 1, 2, 3]), (len(v), 1)), target=ARRAY_BUFFER),
                 "WEIGHTS_0": weights}
        prim = {"attributes": attrs, "material": material,
                "indices": b.accessor(p.faces.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER)}
        if p.node == "face":  # the eyes carry no expression
            prim["targets"] = [{"POSITION": b.accessor(deltas[e][p.ids], minmax=True, target=ARRAY_BUFFER)}
                               for e in EXPRESSIONS]
        else:
            prim["targets"] = [{"POSITION": b.accessor(np.zeros_like(v), minmax=True, target=ARRAY_BUFFER)}
                               for _ in EXPRESSIONS]
        prims.append(prim)
    mesh = b.add("meshes", {"name": "face", "primitives": prims, "weights": [0.0] * len(EXPRESSIONS),
                            "extras": {"targetNames": list(EXPRESSIONS)}})
    jaw = b.add("nodes", {"name": "jaw", "translation": list(JAW - HEAD)})
    head_node = b.add("nodes", {"name": "head", "translation": list(HEAD - NECK), "children": [jaw]})
    neck = b.add("nodes", {"name": "neck", "translation": list(NECK - ROOT), "children": [head_node]})
    root = b.add("nodes", {"name": "root", "translation": list(ROOT), "children": [neck]})
    joints = [root, neck, head_node, jaw]
    ibm = np.stack([np.eye(4)] * 4)
    ibm[:, :3, 3] = -np.stack([ROOT, NECK, HEAD, JAW])  # bind pose: joints unrotated at their world positions
    skin = b.add("skins", {"joints": joints, "skeleton": root, "inverseBindMatrices": b.accessor(
        ibm.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32), "MAT4")})
    body = b.add("nodes", {"name": "face", "mesh": mesh, "skin": skin})
    b.add("scenes", {"nodes": [root, body]})

    times = (np.arange(int(DURATION * FPS) + 1) / FPS).astype(np.float32)
    phase = 2 * np.pi * times / DURATION
    neck_q = _quat_keys(times, 12 * np.sin(2 * phase), 30 * np.sin(phase))  # pitch 12, yaw 30 degrees
    head_q = _quat_keys(times, -15 * np.sin(phase) ** 2, 0 * times)  # the head nods back against the neck
    jaw_q = _quat_keys(times, 20 * np.sin(phase / 2) ** 2, 0 * times)  # opens to 20 degrees at 1 s
    morph = np.stack([np.sin(phase) ** 2, np.clip(np.sin(phase / 2), 0, 1), times / DURATION], 1)
    t = b.accessor(times[:, None], minmax=True)
    samplers, channels = [], []
    for node, path, values in ((neck, "rotation", neck_q), (head_node, "rotation", head_q), (jaw, "rotation", jaw_q),
                               (body, "weights", morph.astype(np.float32).reshape(-1, 1))):
        samplers.append({"input": t, "output": b.accessor(values, "SCALAR" if path == "weights" else None),
                         "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
    b.add("animations", {"name": "talk_and_turn", "samplers": samplers, "channels": channels})
    return b.glb()
