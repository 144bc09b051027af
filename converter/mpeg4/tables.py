"""Face definition tables (what each low-level FAP moves, by how much, which way), built automatically from an FDP."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from converter.errors import InputError
from converter.mpeg4 import influence
from converter.mpeg4.fdp import Fdp, fapu_from_points
from converter.mpeg4.standard import FAPU_NAMES, fap_table
from converter.userfiles import read_bytes, write_atomic

FORMAT = "facesvg-facedeftables"

# Influence radius of a feature point per FAP group, as a multiple of a FAPU neutral distance (section 12.3.2
# leaves the extent to "normalisation"; a raised-cosine falloff keeps far skin still).
GROUP_RADIUS = {2: ("MW0", 0.5), 3: ("IRISD0", 1.2), 4: ("ES0", 0.45), 5: ("ES0", 0.5), 8: ("MW0", 0.5),
                9: ("ENS0", 0.5), 10: ("ENS0", 0.5)}
# Feature points that follow the lower jaw (1), stay with the skull (0) or sit between (mouth corners).
JAW_POINTS = {"2.1": 1.0, "2.3": 1.0, "2.8": 1.0, "2.9": 1.0, "2.10": 1.0, "2.11": 1.0, "2.12": 1.0, "2.13": 1.0,
              "2.14": 1.0, "8.2": 1.0, "8.7": 1.0, "8.8": 1.0, "2.4": 0.4, "2.5": 0.4, "8.3": 0.4, "8.4": 0.4}
JAW_RADIUS = ("MW0", 0.8)
SMOOTH_RADIUS = ("MW0", 0.12)  # weight fields are diffused over about this distance along the skin
EYE_FAPS = {"left_eye": (23, 25, 27), "right_eye": (24, 26, 28)}  # yaw, pitch, thrust
TONGUE_FAPS = {43: "6.1", 44: "6.1", 45: "6.1", 46: "6.2"}
RIGID_PARTS = ("left_eye", "right_eye", "upper_teeth", "lower_teeth", "tongue")


@dataclass(eq=False)
class FapEntry:
    """What one FAP does: translate ids by weight * value * FAPU along direction, or rotate them about pivot/axis.

    For a rotation the angle is weight * value * FAPU / radius (radius 1 for AU FAPs; the chin's distance to the
    jaw pivot for open_jaw, so the chin moves value * MNS). ids None means every vertex; weights None means 1.
    group names rigid sets that rotate together (head, left_eye, right_eye) or "jaw".
    """

    kind: str  # "translate" | "rotate"
    ids: np.ndarray | None
    weights: np.ndarray | None
    direction: np.ndarray  # unit translation direction or rotation axis (model coordinates)
    pivot: np.ndarray | None = None
    radius: float = 1.0
    group: str = ""


@dataclass(eq=False)
class FaceDefTables:
    """Deformation data for every animatable low-level FAP of one mesh, plus why the others are not animated."""

    n_vertices: int
    axes: np.ndarray  # (3, 3) rows: the face's x (to its left), y (up), z (forward) in model coordinates
    fapu: dict[str, float]
    entries: dict[int, FapEntry]
    missing: dict[int, str] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """Plain JSON-able dict (weights rounded to 1e-5)."""
        def arr(a, nd=None):
            return None if a is None else (np.round(a.astype(float), nd).tolist() if nd else a.tolist())

        return {
            "format": FORMAT, "version": 1, "n_vertices": self.n_vertices, "axes": arr(self.axes, 9),
            "fapu": {k: self.fapu[k] for k in FAPU_NAMES if k in self.fapu},
            "entries": {str(f): {"kind": e.kind, "ids": arr(e.ids), "weights": arr(e.weights, 5),
                                 "direction": arr(e.direction, 9), "pivot": arr(e.pivot, 6),
                                 "radius": round(float(e.radius), 9), "group": e.group}
                        for f, e in sorted(self.entries.items())},
            "missing": {str(f): why for f, why in sorted(self.missing.items())},
            "info": self.info,
        }

    def save(self, path: str | Path) -> None:
        """Write as JSON (atomically)."""
        write_atomic(Path(path), json.dumps(self.to_json(), separators=(",", ":")).encode())

    @classmethod
    def from_json(cls, data: dict, name: str = "tables") -> FaceDefTables:
        """Rebuild from to_json() output; InputError when it is not a tables file."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"{name} is not a facesvg face definition tables file.")
        try:
            entries = {}
            for f, e in data["entries"].items():
                entries[int(f)] = FapEntry(
                    e["kind"], None if e["ids"] is None else np.asarray(e["ids"], np.int64),
                    None if e["weights"] is None else np.asarray(e["weights"], np.float32),
                    np.asarray(e["direction"], np.float64), None if e["pivot"] is None else np.asarray(e["pivot"]),
                    float(e["radius"]), e.get("group", ""))
            return cls(int(data["n_vertices"]), np.asarray(data["axes"], np.float64), dict(data["fapu"]), entries,
                       {int(k): v for k, v in data.get("missing", {}).items()}, dict(data.get("info", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{name} is a damaged tables file ({exc}); rebuild it.") from None

    @classmethod
    def load(cls, path: str | Path) -> FaceDefTables:
        """Read a tables JSON file."""
        path = Path(path)
        raw = read_bytes(path, "tables file")
        try:
            data = json.loads(raw)
        except ValueError as exc:
            raise InputError(f"cannot read tables file {path}: {exc}.") from None
        return cls.from_json(data, path.name)


def face_axes(pos: dict[str, np.ndarray], extra: dict | None = None) -> np.ndarray:
    """The face's frame: x from the right to the left pupil, y the model's up made square to it, z = x cross y.

    MPEG-4 faces look along +z with y up; taking x from the pupils also handles a face turned or tilted about y/z.
    An FDP may give its own "axes" (3x3 rows) in extra.
    """
    if extra and "axes" in extra:
        return np.asarray(extra["axes"], np.float64)
    if "3.5" in pos and "3.6" in pos:
        x = pos["3.5"] - pos["3.6"]
        if np.linalg.norm(x) > 0:
            x = x / np.linalg.norm(x)
            y = np.array([0.0, 1.0, 0.0]) - x * x[1]
            if np.linalg.norm(y) > 1e-6:
                y /= np.linalg.norm(y)
                return np.stack([x, y, np.cross(x, y)])
    return np.eye(3)


def sphere_center(points: np.ndarray) -> np.ndarray:
    """Least-squares sphere centre of points (centroid when degenerate)."""
    p = points.astype(np.float64)
    a = np.c_[2 * p, np.ones(len(p))]
    b = (p ** 2).sum(1)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    c = sol[:3]
    return c if np.isfinite(c).all() and np.linalg.norm(c - p.mean(0)) < np.ptp(p, axis=0).max() else p.mean(0)


def jaw_pivot(pos: dict[str, np.ndarray], axes: np.ndarray, fapu: dict[str, float], extra: dict) -> np.ndarray:
    """The jaw's hinge point: given in the FDP extra, else behind and below the eyes (temporomandibular joint)."""
    if "jaw_pivot" in extra:
        return np.asarray(extra["jaw_pivot"], np.float64)
    eyes = (pos["3.5"] + pos["3.6"]) / 2 if "3.5" in pos and "3.6" in pos else pos["2.1"] + axes[1] * 2 * fapu["MNS0"]
    ens = fapu.get("ENS0", fapu.get("MNS0", 1.0) * 1.5)
    es = fapu.get("ES0", fapu.get("MW0", 1.0) * 1.3)
    return eyes - axes[1] * 0.5 * ens - axes[2] * 1.0 * es


def _unit_at(col: np.ndarray, idx: np.ndarray, vertex: int) -> np.ndarray:
    """Scale a smoothed weight column so its feature point's own weight is 1 (a FAP moves its point by its value)."""
    at = col[idx == vertex]
    return np.clip(col / at[0], 0.0, 1.0) if at.size and at[0] > 1e-6 else col


def build_tables(vertices: np.ndarray, faces: np.ndarray, fdp: Fdp) -> FaceDefTables:
    """Deformation data for a neutral mesh (V,3) with triangles (F,3) and its FDP (section 12.3.2)."""
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    n = len(vertices)
    fdp.check(n)
    pos = fdp.point_positions(vertices)
    fapu = {**fapu_from_points(vertices, pos), **fdp.fapu}
    lacking = [k for k in ("MW0", "MNS0") if k not in fapu]
    if lacking:
        raise InputError(f"the FDP cannot give FAPU {', '.join(lacking)} (needs points 2.2, 9.15, 8.3/8.4 or "
                         "2.4/2.5, or a fapu entry); add them or run `facesvg fdp --auto`.")
    axes = face_axes(pos, fdp.extra)
    parts = {k: np.unique(np.asarray(v, np.int64)) for k, v in fdp.parts.items() if len(v)}
    rigid = np.zeros(n, bool)
    for k in RIGID_PARTS:
        if k in parts:
            rigid[parts[k]] = True
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    movable = used & ~rigid
    cut = None
    if all(k in pos for k in ("2.2", "2.3", "2.4", "2.5")):
        # a closed mouth is opened along the lip line so the lips get separate influence (section 12.3.2's holes)
        mid = (pos["2.2"] + pos["2.3"]) / 2
        cut = influence.mouth_cut(vertices, influence.mesh_edges(faces), (pos["2.4"], pos["2.5"]), mid, axes,
                                  0.3 * fapu["MNS0"])
    graph = influence.edge_graph(vertices, faces, keep=~rigid, cut=cut)
    on_skin = {k: v for k, v in fdp.points.items() if movable[v]}
    if not on_skin:
        raise InputError("no FDP feature point lies on the deformable skin; check the FDP's vertex ids.")
    names = sorted(on_skin, key=lambda s: tuple(int(x) for x in s.split(".")))
    src = np.array([on_skin[k] for k in names])
    radius_of = {g: fapu.get(u, fapu["MW0"]) * m for g, (u, m) in GROUP_RADIUS.items()}
    jaw_r = fapu[JAW_RADIUS[0]] * JAW_RADIUS[1]
    limit = max(max(radius_of.values()), jaw_r) * 1.01
    dist_all = influence.geodesic(graph, src, limit=np.inf)
    copy_from = influence.attach_unreachable(graph, vertices, src, movable)
    dist_all = dist_all[:, copy_from]
    dist_all[:, ~movable] = np.inf
    row = {k: i for i, k in enumerate(names)}
    smooth_op = influence.smoothing_operator(graph)
    n_smooth = influence.smoothing_iterations(graph, fapu[SMOOTH_RADIUS[0]] * SMOOTH_RADIUS[1])

    def smoothed(idx: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        full = np.zeros((n, w.shape[1]))
        full[idx] = w
        full = influence.smooth(smooth_op, full, n_smooth)
        full[~movable] = 0.0
        keep = np.flatnonzero((full > 1e-4).any(1))
        return keep, full[keep]

    table = fap_table()
    entries: dict[int, FapEntry] = {}
    missing: dict[int, str] = {}

    # Translations, one influence computation per displacement direction (section 12.3.2.2).
    by_axis: dict[int, list] = {0: [], 1: [], 2: []}
    for f in table:
        if f.is_translation and f.group in GROUP_RADIUS and f.fdp in row and f.number not in (27, 28):
            by_axis[f.axis_index].append(f)
    for ax, faps in by_axis.items():
        fps = sorted({f.fdp for f in faps}, key=lambda s: row[s])
        if not fps:
            continue
        d = dist_all[[row[p] for p in fps]]
        near = np.isfinite(d).any(0) & (d.min(0) <= limit)
        idx = np.flatnonzero(near)
        w = influence.influence_weights(vertices[idx], np.stack([pos[p] for p in fps]), d[:, idx])
        radii = np.array([radius_of[next(f.group for f in faps if f.fdp == p)] for p in fps])
        w *= influence.raised_cosine(d[:, idx].T / radii[None, :])
        idx, w = smoothed(idx, w)
        for f in faps:
            if f.number in (3, 14, 15):
                continue  # jaw FAPs move the jaw region (below)
            col = w[:, fps.index(f.fdp)]
            col = _unit_at(col, idx, fdp.points[f.fdp])
            keep = col > 1e-4
            entries[f.number] = FapEntry("translate", idx[keep], col[keep].astype(np.float32), f.sign * axes[ax])

    # The jaw: a smooth partition of the skin between jaw and skull feature points, plus rigid lower teeth/tongue.
    jaw_names = [k for k in names if k in JAW_POINTS]
    if "2.1" in pos and jaw_names:
        to_jaw = dist_all[[row[k] for k in jaw_names]].min(0)
        idx = np.flatnonzero(to_jaw < jaw_r)  # beyond jaw_r the falloff is zero
        w = influence.influence_weights(vertices[idx], np.stack([pos[k] for k in names]), dist_all[:, idx])
        jv = np.array([JAW_POINTS.get(k, 0.0) for k in names])
        wj = (w @ jv) * influence.raised_cosine(to_jaw[idx] / jaw_r)
        idx, wj = smoothed(idx, wj[:, None])
        wj = _unit_at(wj[:, 0], idx, fdp.points["2.1"])
        jaw_ids = [idx[wj > 1e-4]]
        jaw_w = [wj[wj > 1e-4]]
        for k in ("lower_teeth", "tongue"):
            if k in parts:
                jaw_ids.append(parts[k])
                jaw_w.append(np.ones(len(parts[k])))
        ids, first = np.unique(np.concatenate(jaw_ids[::-1]), return_index=True)  # rigid parts win
        ww = np.concatenate(jaw_w[::-1])[first].astype(np.float32)
        pivot = jaw_pivot(pos, axes, fapu, fdp.extra)
        # lever = the chin's forward distance from the hinge, so a small opening lowers the chin by value * MNS
        lever = max(float((pos["2.1"] - pivot) @ axes[2]), 1e-6)
        entries[3] = FapEntry("rotate", ids, ww, axes[0].copy(), pivot, lever, "jaw")
        entries[14] = FapEntry("translate", ids, ww, axes[2].copy())
        entries[15] = FapEntry("translate", ids, ww, -axes[0])
    else:
        for f in (3, 14, 15):
            missing[f] = "needs feature point 2.1 (chin) on the skin"

    # Eyeballs rotate (yaw about y, pitch about x) and thrust as rigid parts about their centres.
    for part, (yaw, pitch, thrust) in EYE_FAPS.items():
        if part not in parts:
            for f in (yaw, pitch, thrust, yaw + 6):
                missing[f] = f"needs the {part} part in the FDP"
            continue
        ids = parts[part]
        c = sphere_center(vertices[ids])
        entries[yaw] = FapEntry("rotate", ids, None, axes[1].copy(), c, 1.0, part)
        entries[pitch] = FapEntry("rotate", ids, None, axes[0].copy(), c, 1.0, part)
        entries[thrust] = FapEntry("translate", ids, np.ones(len(ids), np.float32), axes[2].copy())
        missing[yaw + 6] = "pupil dilation needs a separate pupil part; not animated"

    # Tongue: translate the tongue with a falloff from the tip (6.1) or the body centre (6.2).
    for num, fp in TONGUE_FAPS.items():
        f = table[num - 1]
        tongue = parts.get("tongue")
        if tongue is None or (fp not in pos and "6.1" not in pos):
            missing[num] = "needs the tongue part and feature point 6.1"
            continue
        centre = pos.get(fp, pos.get("6.1"))
        dd = np.linalg.norm(vertices[tongue] - centre, axis=1)
        w = influence.raised_cosine(dd / max(dd.max(), 1e-9)).astype(np.float32)
        entries[num] = FapEntry("translate", tongue, w, f.sign * axes[f.axis_index])
    missing[47] = "tongue roll is not animated"

    # Head rotation about the top of the spine (7.1) or a point below the skull behind the jaw.
    head_pivot = pos.get("7.1")
    if head_pivot is None:
        jp = entries[3].pivot if 3 in entries else vertices.mean(0)
        head_pivot = jp - axes[1] * fapu.get("ENS0", fapu["MNS0"]) - axes[2] * 0.3 * fapu.get("ES0", fapu["MW0"])
    for num, ax in ((48, 0), (49, 1), (50, 2)):
        entries[num] = FapEntry("rotate", None, None, axes[ax].copy(), np.asarray(head_pivot, np.float64), 1.0, "head")

    for f in table[2:]:
        if f.number not in entries and f.number not in missing:
            missing[f.number] = f"needs feature point {f.fdp} on the skin"
    info = {"feature_points_on_skin": len(names), "mouth_edges_cut": int(0 if cut is None else cut.sum()),
            "influenced": {str(k): int(0 if e.ids is None else len(e.ids))
                                                                   for k, e in sorted(entries.items())}}
    return FaceDefTables(n, axes, {k: float(v) for k, v in fapu.items()}, entries, missing, info)
