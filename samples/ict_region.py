"""The face region of the ICT FaceKit head (skin, mouth, teeth, eyes), simplified with meshoptimizer.

Shared by samples/make_sample.py and bench/faces.py. Vertices keep their ICT ids, units (cm) and coordinates:
simplification only drops vertices, so every kept vertex sits exactly where it is in the ICT head.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from converter.formats.ictfacekit import EYEBALL_LEFT, EYEBALL_RIGHT, PART_ORDER, IctHead

FACE_VERTICES = 9409  # ICT "Face" geometry: vertex ids [0, 9409)
NARROW_FACE_VERTICES = 6706  # ICT "Narrow face area": vertex ids [0, 6706), no ears or neck
MOUTH_SOCKET = (11248, 13294)  # ICT "Mouth socket" vertex ids, drawn as the mouth interior
# Share of the triangle budget per (piece, part); lashes only when asked for.
BUDGET = {
    ("face", "skin"): 0.62, ("face", "mouth"): 0.09, ("face", "teeth"): 0.09,
    ("eye_left", "eye"): 0.05, ("eye_left", "iris"): 0.05,
    ("eye_right", "eye"): 0.05, ("eye_right", "iris"): 0.05,
    ("face", "lashes"): 0.06,
}
PIECES = ("face", "eye_left", "eye_right")


@dataclass(frozen=True)
class Piece:
    """One part of one rigid group (the face, or one eyeball): its ICT vertex ids and local triangles."""

    node: str  # one of PIECES
    part: str  # one of ictfacekit.PART_ORDER
    ids: np.ndarray  # (V,) ICT vertex ids, in first-use order of the triangles
    faces: np.ndarray  # (F, 3) int32 indices into ids


def classify(head: IctHead, face_vertices: int = FACE_VERTICES) -> tuple[np.ndarray, np.ndarray]:
    """Per ICT triangle: (piece index into PIECES or -1 to drop, part index into PART_ORDER)."""
    f, part = head.faces, head.part_ids.copy()
    skin, mouth = PART_ORDER.index("skin"), PART_ORDER.index("mouth")
    in_socket = (f.min(1) >= MOUTH_SOCKET[0]) & (f.max(1) < MOUTH_SOCKET[1])
    part[(part == skin) & in_socket] = mouth
    piece = np.full(len(f), -1, np.int64)
    on_face = ((part == skin) & (f.max(1) < face_vertices)) | (part == mouth)
    on_face |= np.isin(part, [PART_ORDER.index("teeth"), PART_ORDER.index("lashes")])
    piece[on_face] = 0
    eye = np.isin(part, [PART_ORDER.index("eye"), PART_ORDER.index("iris")])
    piece[eye & (f.min(1) >= EYEBALL_LEFT[0]) & (f.max(1) < EYEBALL_LEFT[1])] = 1
    piece[eye & (f.min(1) >= EYEBALL_RIGHT[0]) & (f.max(1) < EYEBALL_RIGHT[1])] = 2
    return piece, part


def face_region(head: IctHead, triangles: int = 3000, lashes: bool = False, lock_border: bool = True,
                parts: tuple[str, ...] | None = None, face_vertices: int = FACE_VERTICES) -> list[Piece]:
    """The face's parts, then each eye's parts (only `parts` when given), simplified to ~`triangles` in all."""
    import meshoptimizer as mo  # noqa: PLC0415 - only the sample builder needs it

    piece, part = classify(head, face_vertices)
    shares = {k: v for k, v in BUDGET.items()
              if (lashes or k[1] != "lashes") and (parts is None or k[1] in parts)}
    total_share = sum(shares.values())
    out = []
    for pi, pname in enumerate(PIECES):
        for (piece_name, part_name), share in shares.items():
            if piece_name != pname:
                continue
            src = head.faces[(piece == pi) & (part == PART_ORDER.index(part_name))].astype(np.uint32)
            target = max(int(round(triangles * share / total_share)), 8)
            if len(src) > target:
                dst = np.zeros(src.size, np.uint32)
                # The skin's open borders (lips, eyelids, outline) carry the expression: keep them.
                opts = mo.SIMPLIFY_LOCK_BORDER if part_name == "skin" and lock_border else 0
                n = mo.simplify(dst, src.reshape(-1), head.vertices, target_index_count=target * 3,
                                target_error=0.2, options=opts)
                src = dst[:n].reshape(-1, 3)
            flat = src.reshape(-1).astype(np.int64)
            uniq, first = np.unique(flat, return_index=True)
            ids = uniq[np.argsort(first, kind="stable")]
            local = np.zeros(int(ids.max()) + 1, np.int64)
            local[ids] = np.arange(len(ids))
            out.append(Piece(pname, part_name, ids, local[flat].reshape(-1, 3).astype(np.int32)))
    return out
def sphere_center(points: np.ndarray) -> np.ndarray:
    """Least-squares centre of a sphere through points (N, 3): the eyeball's rotation centre."""
    a = np.c_[2 * points, np.ones(len(points))]
    b = (points ** 2).sum(1)
    sol = np.linalg.lstsq(a.astype(np.float64), b.astype(np.float64), rcond=None)[0]
    return sol[:3]
