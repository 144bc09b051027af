"""The puppet: a 2D mesh of a face with named morph targets, and per morph target a 2D FAT (keyform displacements).

The chapter's 2D FAT (section 12.4.4.1) generalised from MPEG-4 FAPs to any named morph target. For every target
the table holds, per keyform, the 2D pixel displacement and NDC depth change of each vertex it moves (sparse:
only those), quantised to int16 with one step per table: keyforms at weights 0 < ... < 1 (the chapter's FAT
intervals), piecewise linear in between and extrapolated from the end intervals; one interval where the
projection of the target is linear within LINEAR_TOL px (an orthographic camera, or a target moving within a plane
facing it). The targets add: xy = xy0 + sum of the displacements, depth the same way, so the player's depth buffer
shows what the opening mouth hides.

Head yaw, pitch and roll and each eye's yaw and pitch are rigid turns, and a vertex's pixel and depth give back
its point (`unproject`, the camera's inverse): the player turns the displaced points in world space, as
blendshapes.drive does (eyes about their fitted sphere centres first, then the head about the centre of the rest
bounding box, R = Ry Rx Rz), and projects them again. That is exact at every angle and costs no table; sampled
angle keyforms (Live2D's AngleX/AngleY, bilinear, a 7 x 7 grid every 10 degrees) were most of the package and
drifted off the exact turn between keyforms. The mesh holds every triangle front-facing at rest, under any single
target at its keyforms, or at any angle of VISIBILITY_GRID: a turn beyond it may show a triangle the puppet lacks.
By default (build's budget) it then keeps only those some sampled pose shows, simplified within a pixel bound where
there are more than the player draws at the display rate (converter/puppet/budget.py).

Colour: the puppet keeps each triangle's (flat) or vertex's (Gouraud) rest normal (octahedral, 2 x int8) and unlit
base colour, and the player lights them as converter.lighting does with the normals turned by the head (`shade`), so
the face relights as it turns; morph displacements and eye turns keep their rest normals.

A pose is exact for any single target at its keyforms combined with any head and eye angles (up to MOVE_PX, the
least motion a table keeps, plus half a quantisation step XY_STEP), and approximate between keyforms and for
several targets together (their 2D displacements add where their 3D ones do; perspective makes the two differ
slightly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import converter.puppet.budget as triangle_budget
from converter.blendshapes import eye_vertices, match_face, normalise, rotations
from converter.camera import Camera
from converter.errors import InputError
from converter.extract import cull, unit_face_normals, unit_vertex_normals
from converter.formats.captures.arkit import NAMES as ARKIT_NAMES
from converter.formats.morphs import MorphFace
from converter.lighting import DEFAULT_LIGHTING, lambert_linear, srgb_to_linear
from converter.mpeg4.tables import sphere_center
from converter.options import Progress, no_progress

MORPH_WEIGHTS = (0.0, 0.25, 0.5, 0.75, 1.0)  # a target's keyforms where its projection is not linear
LINEAR_TOL = 0.05  # px: a target whose projection stays this close to linear in its weight keeps one interval
VISIBILITY_GRID = tuple(float(a) for a in range(-40, 41, 10))  # degrees of head (and eye) yaw and pitch whose
# front-facing triangles the puppet keeps
XY_STEP = 1.0 / 16  # px: the quantisation step of a displacement (coarser only where a table's range needs it)
Z_LEVELS = 1 << 12  # depth steps over the neutral face's depth range: the step of a depth change
NEUTRAL_XY_STEP = 1.0 / 16  # px: the neutral face's positions are snapped to this grid (the package stores integers)
NEUTRAL_Z_STEP = 1.0 / 65536  # NDC: ... and its depths to this one
MOVE_PX = 0.05  # px: a vertex that moves less at every keyform of a target is left out of its table
INT16 = 32767
MOVE_EPS = 0.0  # a vertex is a candidate for a morph's table where any coordinate of its 3D delta differs from this


@dataclass(frozen=True)
class Table:
    """One parameter's keyforms over the vertices it moves: quantised displacements and their steps."""

    vertices: np.ndarray  # int32 (M,) puppet vertex ids, ascending
    xy: np.ndarray  # int16 (S, M, 2) displacement / xy_step per keyform
    z: np.ndarray  # int16 (S, M) depth change / z_step
    xy_step: float
    z_step: float

    def keyform(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(M, 2) px and (M,) NDC displacement of keyform s, dequantised (float64)."""
        return self.xy[s].astype(np.float64) * self.xy_step, self.z[s].astype(np.float64) * self.z_step


@dataclass(frozen=True)
class Parameter:
    """A puppet parameter (a morph target): its name, keyform weights (axes[0], keyform s at weights[s]), table."""

    name: str
    axes: tuple[np.ndarray, ...]
    table: Table
    clamp: bool = False  # a VRM expression: its weight is clamped to 0..1
    binary: bool = False  # a VRM isBinary expression: 1 above 0.5, else 0


@dataclass(frozen=True)
class Take:
    """A weight capture as the puppet stores it: uint8 weights per name per frame, angles as small integers."""

    names: list[str]
    weights: np.ndarray  # uint8 (T, K): round(weight * 255), clamped to 0..1
    fps: float
    head: np.ndarray | None = None  # int16 (T, 3) yaw, pitch, roll in HEAD_UNIT
    eyes: np.ndarray | None = None  # int8 (T, 4) left yaw, pitch, right yaw, pitch in EYE_UNIT
    times: np.ndarray | None = None  # uint16 (T,) ms since the previous frame, where the take is irregular
    source: str = ""

    @property
    def n_frames(self) -> int:
        """Frames T."""
        return int(self.weights.shape[0])

    @property
    def bytes_per_frame(self) -> int:
        """Stored bytes a frame (weights, angles, times)."""
        n = self.weights.shape[1]
        n += 6 if self.head is not None else 0
        n += 4 if self.eyes is not None else 0
        return n + (2 if self.times is not None else 0)


HEAD_UNIT = math.pi / 18000  # radians per stored unit: 0.01 degree (int16 covers +-327 degrees)
EYE_UNIT = math.pi / 360  # 0.5 degree (int8 covers +-63.5 degrees)


@dataclass(frozen=True, eq=False)
class Puppet:
    """The 2D puppet of a face: mesh, appearance and parameter tables (see the module docstring)."""

    name: str
    camera: Camera
    xy: np.ndarray  # float32 (V, 2) px of the neutral face
    z: np.ndarray  # float32 (V,) NDC depth of the neutral face
    source_vertices: np.ndarray  # int32 (V,) the face's vertex of each puppet vertex
    triangles: np.ndarray  # int32 (F, 3) puppet vertex ids, counter-clockwise in GL (negative area with y down)
    source_triangles: int  # the face's triangle count
    colors: np.ndarray  # uint8 (F, 3) flat or (V, 3) Gouraud display colours of the neutral face
    gouraud: bool
    pivot: np.ndarray  # float64 (3,) world: the head's pivot (the centre of the rest bounding box)
    morphs: tuple[Parameter, ...]
    eyes: tuple[np.ndarray, ...]  # () or (left, right): int32 puppet vertex ids of each eye
    eye_centres: np.ndarray  # float64 (2, 3) world: each eye's turning centre (or (0, 3))
    aliases: dict[str, list[tuple[int, float]]]  # capture name -> (morph index, factor) pairs
    keys: tuple[tuple[str, str], ...]  # normalised (base, side) of each morph name
    take: Take | None = None
    info: dict = field(default_factory=dict)
    normals: np.ndarray | None = None  # int8 (F, 2) flat or (V, 2) Gouraud rest unit normals, octahedral * 127
    base_colors: np.ndarray | None = None  # uint8 (F, 3) or (V, 3) unlit display base colours: the player relights

    @property
    def width(self) -> int:
        """Viewport width in px."""
        return self.camera.width

    @property
    def height(self) -> int:
        """Viewport height in px."""
        return self.camera.height

    def with_take(self, take: Take | None) -> Puppet:
        """The same puppet carrying another take."""
        return Puppet(**{**self.__dict__, "take": take})


def _quantise(xy: np.ndarray, z: np.ndarray, z_unit: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """int16 xy and z of float arrays with one step each: XY_STEP px and z_unit, coarser only where the range needs."""
    xy_max = float(np.abs(xy).max()) if xy.size else 0.0
    z_max = float(np.abs(z).max()) if z.size else 0.0
    xy_step = max(XY_STEP, xy_max / INT16)
    z_step = max(z_unit, z_max / INT16)
    qxy = np.clip(np.rint(xy / xy_step), -INT16, INT16).astype(np.int16)
    qz = np.clip(np.rint(z / z_step), -INT16, INT16).astype(np.int16)
    return qxy, qz, float(xy_step), float(z_step)


def _table(ids: np.ndarray, xy: np.ndarray, z: np.ndarray, z_unit: float) -> Table:
    """A Table of keyform displacements (S, M, 2) and (S, M) at vertices ids, keeping only the vertices that move
    MOVE_PX or more (or change depth by more than a step) at some keyform."""
    qxy, qz, xs, zs = _quantise(xy, z, z_unit)
    moves = (np.abs(xy).max(axis=(0, 2), initial=0.0) >= MOVE_PX) | (qz != 0).any(axis=0)
    return Table(ids[moves].astype(np.int32), np.ascontiguousarray(qxy[:, moves]),
                 np.ascontiguousarray(qz[:, moves]), xs, zs)


def _project(camera: Camera, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel xy and NDC z of points (..., 3)."""
    xy, z, _ = camera.project(pts)
    return xy, z


def unproject(camera: Camera, xy: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World points (N, 3) of pixel xy (N, 2) and NDC depth (N,): Camera.project's inverse."""
    m = np.linalg.inv(camera.projection @ camera.view)
    ndc = np.stack([np.asarray(xy[:, 0], np.float64) / camera.width * 2 - 1,
                    1 - np.asarray(xy[:, 1], np.float64) / camera.height * 2,
                    np.asarray(z, np.float64), np.ones(len(z))], axis=1)
    p = ndc @ m.T
    return p[:, :3] / p[:, 3:]


def _grid() -> tuple[np.ndarray, np.ndarray]:
    """The (yaws, pitches) whose poses decide the kept triangles, in radians."""
    a = np.radians(np.array(VISIBILITY_GRID, np.float64))
    return a, a.copy()


def _turned(points: np.ndarray, centre: np.ndarray, yaws: np.ndarray, pitches: np.ndarray) -> np.ndarray:
    """(Y * P, N, 3) points turned about centre by every (yaw, pitch) of the grid, as blendshapes.drive turns them
    (float32 rotations and pivot)."""
    ypr = np.array([[y, p, 0.0] for y in yaws for p in pitches], np.float32)
    r = rotations(ypr).astype(np.float32)
    c = centre.astype(np.float32)
    return (points.astype(np.float32) - c) @ np.swapaxes(r, 1, 2) + c


def build(face: MorphFace, camera: Camera, gouraud: bool = False, progress: Progress = no_progress,
          budget: bool = True) -> Puppet:
    """The puppet of a face seen by a camera (see the module docstring); progress("puppet", fraction). With budget
    (the default) only the triangles some sampled pose shows are kept, simplified within budget.BOUND_PX."""
    base = face.base.astype(np.float32)
    faces = face.faces.astype(np.int64)
    xy0, z0 = _project(camera, base)
    w_cam = camera.project(base)[2]
    shown = np.zeros(len(faces), bool)  # triangles front-facing and in view in some pose the puppet can take

    def see(xy: np.ndarray, z: np.ndarray, w: np.ndarray) -> None:
        """Mark the triangles a pose (or a block of poses) shows: float64 (n, V, ...), as extraction culls its
        projections (the compiled kernel keeps one signature, tests/core/test_warm)."""
        shown[:] |= cull(xy, z, w, faces, camera.width, camera.height).any(axis=0)

    def see_part(ids: np.ndarray, xy: np.ndarray, z: np.ndarray) -> None:
        """see() the poses (n, len(ids), ...) of some vertices, the others at rest (w at rest: a face in front of the
        eye stays in front of it)."""
        full_xy = np.repeat(xy0[None], len(xy), axis=0)
        full_z = np.repeat(z0[None], len(xy), axis=0)
        full_xy[:, ids], full_z[:, ids] = xy, z
        see(full_xy, full_z, np.repeat(w_cam[None], len(xy), axis=0))

    see(xy0[None], z0[None], w_cam[None])
    z_unit = float(np.ptp(z0)) / Z_LEVELS or 1e-9  # the depth step: the face's depth range over Z_LEVELS
    morph_raw = []
    n_k = len(face.names)
    for k in range(n_k):
        d = face.deltas[k]
        ids = np.flatnonzero(np.any(d != MOVE_EPS, axis=1))
        w = np.array(MORPH_WEIGHTS, np.float32)
        pts = base[ids][None] + w[:, None, None] * d[ids][None]
        kxy, kz = _project(camera, pts)
        dxy, dz = kxy - xy0[ids], kz - z0[ids]
        lin_xy = w[:, None, None] * dxy[-1][None]
        lin_z = w[:, None] * dz[-1][None]
        err = float(np.abs(dxy - lin_xy).max()) if len(ids) else 0.0
        z_err = float(np.abs(dz - lin_z).max()) if len(ids) else 0.0
        if err <= LINEAR_TOL and z_err <= z_unit:  # NDC depth is never linear in perspective: within a step
            keep = np.array([0, len(w) - 1])
        else:
            keep = np.arange(len(w))
        morph_raw.append((ids, w[keep].astype(np.float64), dxy[keep], dz[keep]))
        see_part(ids, kxy[-1:], kz[-1:])
        progress("puppet", 0.4 * (k + 1) / max(n_k, 1))

    lo, hi = face.base.min(0), face.base.max(0)
    pivot3 = (0.5 * (lo + hi)).astype(np.float32)
    yaws, pitches = _grid()
    for y in yaws:  # a row of the grid at a time: the poses of a dense head are tens of MB each row
        turned = _turned(base, pivot3, np.array([y]), pitches)
        txy, tz, tw = camera.project(turned)
        see(txy, tz, tw)
    progress("puppet", 0.6)

    sides = eye_vertices(face)
    centres = []
    for ids in sides or ():
        centre = sphere_center(face.base[ids]).astype(np.float32)
        centres.append(centre)
        exy, ez = _project(camera, _turned(base[ids], centre, yaws, pitches))
        see_part(ids, exy, ez)
    progress("puppet", 0.7)

    if not shown.any():
        raise InputError("no triangle of the face is ever visible from this camera (all face away, lie outside the "
                         "view or have no area); check --yaw/--pitch or the mesh's winding.")
    facing = int(shown.sum())
    if budget:  # only what some pose shows, simplified within budget.BOUND_PX (see converter/puppet/budget.py)
        shown &= triangle_budget.seen(face, camera, pivot3, shown)
        occluded = facing - int(shown.sum())
        mesh, mesh_parts = triangle_budget.simplified(face, camera, shown) if shown.any() else (
            faces[shown], face.part_ids[shown])
    else:
        occluded, mesh, mesh_parts = 0, faces[shown], face.part_ids[shown]
    if not len(mesh):
        raise InputError("no triangle of the face is ever visible from this camera (all hidden behind others); "
                         "check --yaw/--pitch or the mesh's winding.")
    mesh = mesh.astype(np.int64)
    # in order of their vertices (the package stores the corners as differences: nearby ids deflate well)
    order = np.lexsort((mesh.max(axis=1), mesh.min(axis=1)))
    mesh, mesh_parts = mesh[order], mesh_parts[order]
    used = np.unique(mesh)
    remap = np.full(len(base), -1, np.int64)
    remap[used] = np.arange(len(used))

    def sparse(ids: np.ndarray, dxy: np.ndarray, dz: np.ndarray) -> Table:
        inside = remap[ids] >= 0
        return _table(remap[ids[inside]], dxy[:, inside], dz[:, inside], z_unit)

    exprs = {x.index: x.expression for x in face.expressions}
    morphs = tuple(
        Parameter(face.names[k], (wk,), sparse(ids, dxy, dz), clamp=k in exprs,
                  binary=bool(k in exprs and exprs[k].binary))
        for k, (ids, wk, dxy, dz) in enumerate(morph_raw))
    eyes = tuple(remap[ids][remap[ids] >= 0].astype(np.int32) for ids in sides or ())
    progress("puppet", 0.8)

    tris = remap[mesh].astype(np.int32)
    neutral = base[None]
    if gouraud:  # the full mesh's vertex normals: the simplified surface keeps the face's smooth shading
        base_display = face.still(1.0).face_base_colors()
        base_rgb = srgb_to_linear(base_display[None])
        rest_normals = unit_vertex_normals(neutral, faces)
        rgb = lambert_linear(rest_normals, base_rgb, camera.view, DEFAULT_LIGHTING)[0][used]
        rest_normals, base_display = rest_normals[0][used], base_display[used]
    else:
        still = face.still(1.0)
        on_mesh = still.with_frames(still.frames, faces=mesh.astype(np.int32), part_ids=mesh_parts)
        base_display = on_mesh.triangle_colors()
        tri_lin = srgb_to_linear(base_display[None])
        rest_normals = unit_face_normals(neutral, mesh)
        rgb = lambert_linear(rest_normals, tri_lin, camera.view, DEFAULT_LIGHTING)[0]
        rest_normals = rest_normals[0]
    colors = np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)
    normals8 = octahedral(np.nan_to_num(rest_normals))
    base8 = np.clip(np.rint(np.nan_to_num(base_display) * 255), 0, 255).astype(np.uint8)
    aliases = _aliases(face)
    info = {"vertices": int(len(used)), "triangles": int(len(mesh)), "source_vertices": int(len(base)),
            "source_triangles": int(len(faces)), "morphs": n_k, "facing_triangles": facing,
            "occluded_triangles": occluded, "budget_px": triangle_budget.BOUND_PX if budget else 0.0,
            "morph_intervals": int(sum(len(p.axes[0]) - 1 for p in morphs)),
            "eyes": int(bool(eyes))}
    progress("puppet", 1.0)
    snapped_xy = (np.rint(xy0[used] / NEUTRAL_XY_STEP) * NEUTRAL_XY_STEP).astype(np.float32)
    snapped_z = (np.rint(z0[used] / NEUTRAL_Z_STEP) * NEUTRAL_Z_STEP).astype(np.float32)
    return Puppet(face.name, camera, snapped_xy, snapped_z,
                  used.astype(np.int32), tris, int(len(faces)), colors, bool(gouraud), pivot3.astype(np.float64),
                  morphs, eyes, np.array(centres, np.float64).reshape(-1, 3), aliases,
                  tuple(normalise(n) for n in face.names), None, info, normals8, base8)


def octahedral(normals: np.ndarray) -> np.ndarray:
    """int8 (N, 2) octahedral codes * 127 of unit normals (N, 3): the octahedron's faces folded onto a square."""
    n = np.asarray(normals, np.float64)
    o = n[:, :2] / np.maximum(np.abs(n).sum(axis=1, keepdims=True), 1e-12)
    low = n[:, 2] < 0
    o[low] = (1 - np.abs(o[low][:, ::-1])) * np.where(o[low] >= 0, 1.0, -1.0)
    return np.clip(np.rint(o * 127), -127, 127).astype(np.int8)


def unoctahedral(codes: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) float64 of octahedral codes (N, 2) (the player's decoding)."""
    o = np.asarray(codes, np.float64) / 127
    z = 1 - np.abs(o).sum(axis=1)
    t = np.maximum(-z, 0.0)[:, None]
    xy = o - np.where(o >= 0, t, -t)
    n = np.c_[xy, z]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def shade(puppet: Puppet, head: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """uint8 (N, 3) display colours of the puppet's triangles (flat) or vertices (Gouraud) with the head turned
    (yaw, pitch, roll radians): its stored rest normals turned by the head and lit as converter.lighting lights them
    (what the player draws; morphs and eye turns keep their rest normals)."""
    n = unoctahedral(puppet.normals)
    r = rotations(np.array([list(head)], np.float64))[0]
    lit = lambert_linear((n @ r.T).astype(np.float32), srgb_to_linear(puppet.base_colors / 255.0),
                         puppet.camera.view, DEFAULT_LIGHTING)
    return np.clip(np.rint(lit * 255), 0, 255).astype(np.uint8)


def _aliases(face: MorphFace) -> dict[str, list[tuple[int, float]]]:
    """What each ARKit name drives on the face (blendshapes.match_face: by name, or a VRM face's preset table)."""
    names = [n for n in ARKIT_NAMES if n not in face.names]
    m = match_face(names, face)
    out = {}
    for i, n in enumerate(names):
        js = np.flatnonzero(m.mapping[i])
        if len(js):
            out[n] = [(int(j), float(m.mapping[i, j])) for j in js]
    return out


def resolve(puppet: Puppet, names: list[str]) -> np.ndarray:
    """(len(names), K) float32 mapping of named weights onto the puppet's morphs, as the player resolves names:
    the morph's own name, else the stored aliases, else the normalised name (a sideless name drives both sides)."""
    own = {p.name: k for k, p in enumerate(puppet.morphs)}
    by_key: dict[tuple[str, str], list[int]] = {}
    for k, key in enumerate(puppet.keys):
        by_key.setdefault(key, []).append(k)
    m = np.zeros((len(names), len(puppet.morphs)), np.float32)
    for i, n in enumerate(names):
        if n in own:
            m[i, own[n]] = 1.0
        elif n in puppet.aliases:
            for k, f in puppet.aliases[n]:
                m[i, k] += f
        else:
            base, side = normalise(n)
            hits = by_key.get((base, side), [])
            if not hits and not side:  # a sideless name drives both sides
                hits = by_key.get((base, "L"), []) + by_key.get((base, "R"), [])
            m[i, hits] = 1.0
    return m


def _segment(axis: np.ndarray, x: float) -> tuple[int, float]:
    """(interval index i, fraction) of x on a sorted axis: extrapolated from the end intervals."""
    i = int(np.clip(np.searchsorted(axis, x, side="right") - 1, 0, len(axis) - 2))
    return i, (x - axis[i]) / (axis[i + 1] - axis[i])


def morph_weight(p: Parameter, w: float) -> float:
    """The weight a morph parameter applies: a VRM expression's clamped (and binary) weight, else as given."""
    if p.clamp:
        w = min(max(w, 0.0), 1.0)
    if p.binary:
        w = 1.0 if w > 0.5 else 0.0
    return w


def pose(puppet: Puppet, weights: np.ndarray, head: tuple[float, float, float] = (0.0, 0.0, 0.0),
         eyes: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """The puppet's (V, 2) px and (V,) NDC depth for morph weights (K,), head (yaw, pitch, roll) and eyes (left yaw,
    pitch, right yaw, pitch) in radians: what the player draws (the reference evaluator, float64)."""
    xy = puppet.xy.astype(np.float64)
    z = puppet.z.astype(np.float64)
    for p, w in zip(puppet.morphs, np.asarray(weights, np.float64)):
        w = morph_weight(p, float(w))
        if w == 0.0 or not len(p.table.vertices):
            continue
        i, a = _segment(p.axes[0], w)
        x0, z0 = p.table.keyform(i)
        x1, z1 = p.table.keyform(i + 1)
        xy[p.table.vertices] += (1 - a) * x0 + a * x1
        z[p.table.vertices] += (1 - a) * z0 + a * z1
    yaw, pitch, roll = (float(a) for a in head)
    turn_eyes = [k for k in range(len(puppet.eyes)) if eyes[2 * k] or eyes[2 * k + 1]]
    if yaw or pitch or roll:
        sel = np.arange(len(xy))
    elif turn_eyes:
        sel = np.unique(np.concatenate([puppet.eyes[k] for k in turn_eyes]))
    else:
        return xy, z
    q = np.zeros((len(xy), 3))
    q[sel] = unproject(puppet.camera, xy[sel], z[sel])
    for k in turn_eyes:  # drive turns the eyes of the morphed face about their centres, then the head
        ids, c = puppet.eyes[k], puppet.eye_centres[k]
        r = rotations(np.array([[eyes[2 * k], eyes[2 * k + 1], 0.0]]))[0]
        q[ids] = (q[ids] - c) @ r.T + c
    if yaw or pitch or roll:
        r = rotations(np.array([[yaw, pitch, roll]]))[0]
        q = (q - puppet.pivot) @ r.T + puppet.pivot
    xy[sel], z[sel] = _project(puppet.camera, q[sel])
    return xy, z
