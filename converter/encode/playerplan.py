"""The player's plan: per-vertex keys (optionally under one head transform), per-path visibility and colour keys.

What converter.writers.player packs and deflates (its module docstring says how the script plays it): the paths
in the SVG's drawing order (order.draw_list, never-shown ones dropped), each vertex stored once with one keyframed
2D track within the tolerance (freeknots, Euclidean bound per point; with options.rigid, when it saves key bytes,
local to the largest part's affine map per frame), and colours as linear keys within COLOR_LEVELS levels
(colours.color_keys: per path for flat shading, per vertex for Gouraud).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse

from converter.encode import colours, freeknots, groups, robust_affine
from converter.encode import keys as keyframes
from converter.encode.budget import ErrorBudget
from converter.encode.order import draw_list
from converter.options import ConversionOptions, Progress, no_progress, span
from converter.sheet import Sheet

BYTES_PER_KEY = 2.5  # deflated bytes of a position key (capture-like), against the head transform's float32s
COLOR_LEVELS = 3.0  # colour keys within this many 8-bit levels (the SVG's exact colours): colour costs the GPU nothing


class PlayerPlan(NamedTuple):
    """Everything the player stores, as numbers (see ``plan``)."""

    budget: ErrorBudget
    tris: np.ndarray  # int64 (P,) the triangle of each path, back to front
    active: np.ndarray  # bool (T, P) the path shows at the frame
    verts: np.ndarray  # int64 (V,) the input vertex of each stored vertex
    local: np.ndarray  # int64 (P, 3) stored vertices of each path
    positions: keyframes.Keys  # per stored vertex, values on the budget's integer grid (px x scale)
    head: np.ndarray | None  # float32 (T + 1, 2, 3) head transform per frame (positions are local to it), or None
    colours: keyframes.Keys  # linear colour keys per path (flat) or per stored vertex (gouraud), 8-bit levels
    gouraud: bool
    conflicts: int  # depth-order conflicts (order.draw_list)


def vertex_active(active: np.ndarray, path_vertices: np.ndarray, n_vertices: int) -> np.ndarray:
    """Bool (T, V): a vertex is active where any path using it is shown."""
    p = len(path_vertices)
    inc = sparse.csr_matrix((np.ones(3 * p), (np.repeat(np.arange(p), 3), path_vertices.ravel())),
                            shape=(p, n_vertices))
    return np.asarray((inc.T @ sparse.csr_matrix(active.T.astype(np.float64))).todense().T) > 0


def _head(sheet: Sheet, tris: np.ndarray, local: np.ndarray, xy: np.ndarray,
          budget: ErrorBudget) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The head transform: per frame the affine map of the largest part from the neutral frame
    (robust_affine.fit_affine, float32 as stored; frame T repeats frame T-1), the vertices (T, V, 2) in its frame, and
    the radius their keys may use: the map magnifies a local error by at most its largest singular value.
    None when a frame's map is (nearly) singular."""
    part = sheet.part_ids[tris]
    skin = np.unique(local[part == np.bincount(part).argmax()])
    fit = robust_affine.fit_affine(xy[sheet.neutral, skin], xy, skin)
    mats = np.concatenate([fit, fit[-1:]]).astype(np.float32)
    a = mats[:-1].astype(np.float64)
    det = np.linalg.det(a[:, :, :2])
    if not (np.isfinite(a).all() and (np.abs(det) > 1e-3).all()):
        return None
    local_xy = groups.apply_linear(np.linalg.inv(a[:, :, :2]), xy - a[:, None, :, 2])
    gain = float(np.linalg.norm(a[:, :, :2], ord=2, axis=(1, 2)).max())
    radius = (budget.tolerance - budget.float_err) / gain - budget.rounding
    return mats, local_xy, radius


def position_keys(sheet: Sheet, tris: np.ndarray, verts: np.ndarray, local: np.ndarray, vact: np.ndarray,
                  budget: ErrorBudget, rigid: bool,
                  progress: Progress = no_progress) -> tuple[keyframes.Keys, np.ndarray | None]:
    """Per-vertex keys in px, or (with rigid) local to the head transform (_head) when that saves more key bytes
    than the transform costs; the transforms (T + 1, 2, 3) float32 or None. progress(stage, fraction done)."""
    xy = np.take(sheet.xy, verts, axis=1).astype(np.float64)
    # Keys sit on integer frames (nothing to round in time): the keyTimes share is the keyframes' too.
    plain = freeknots.point_keys(xy, vact, budget.tolerance - budget.rounding - budget.float_err,
                                 progress=span(progress, 0.0, 0.45))
    head = _head(sheet, tris, local, xy, budget) if rigid else None
    if head is None or head[2] <= 0.1 * budget.keys:
        return plain, None
    mats, local_xy, radius = head
    keys = freeknots.point_keys(local_xy, vact, radius, progress=span(progress, 0.55, 1.0))
    if (plain.mask.sum() - keys.mask.sum()) * BYTES_PER_KEY <= mats.nbytes:
        return plain, None
    return keys, mats


def plan(sheet: Sheet, options: ConversionOptions, progress: Progress = no_progress) -> PlayerPlan:
    """The player's plan of the sheet's animation; progress(stage, fraction) from the drawing order to the colours
    (0..1)."""
    dl = draw_list(sheet, layers=options.depth_layers)
    shown_any = dl.active.any(axis=0)
    tris, active = dl.triangles[shown_any].astype(np.int64), np.compress(shown_any, dl.active, axis=1)
    p = len(tris)
    progress("keys", 0.05)
    corners = sheet.faces[tris].astype(np.int64)
    verts, local = np.unique(corners, return_inverse=True)
    local = local.reshape(p, 3)
    vact = vertex_active(active, local, len(verts))
    budget = ErrorBudget.split(options.tolerance, max(sheet.camera.width, sheet.camera.height))
    pos, mats = position_keys(sheet, tris, verts, local, vact, budget, options.rigid, span(progress, 0.05, 0.45))
    q = pos._replace(values=np.rint(np.multiply(pos.values, budget.scale, dtype=np.float64)))
    gouraud = options.shading != "flat"
    rgb, cact = ((np.take(sheet.vertex_rgb, verts, axis=1), vact) if gouraud
                 else (sheet.face_colors(tris), active))
    progress("colours", 0.45)
    ck = colours.color_keys(rgb, cact, COLOR_LEVELS)
    return PlayerPlan(budget, tris, active, verts, local, q, mats, ck, gouraud, dl.conflicts)
