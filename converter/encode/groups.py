"""Rigid-motion factoring: a head transform around everything, band transforms inside it, residuals last.

Captured faces sway and jitter as a whole; encoding every triangle's screen motion repeats that motion in every
path. Two levels of animated 2D affine group transforms take it out:

- the *head*: the largest piece (the skin) fitted per frame on screen. It carries the pose jitter, so it is
  keyed nearly every frame, but it is written once: one ``<g>`` around every path of the document.
- *bands*, inside the head's frame: each part's connected pieces (each eye, each iris, teeth, ...) merged where
  one band's motion explains another's, and the skin cut into clusters that move alike once the head's
  motion is taken out (k-means on residual trajectories: a turning head moves its nose and its cheeks
  differently on screen, and brows, jaw and cheeks move on their own).

Each fit is robust least squares from the neutral frame, written as an SMIL transform stack on a ``<g>``:

    translate(tx ty) rotate(a) skewX(k) scale(sx sy)     each an <animateTransform additive="sum">

which is exactly the QR decomposition of the affine map (rotation times upper-triangular), about the band's
centroid (path coordinates are relative to it). Each parameter is keyframed on its own with
``keys.reduce`` and rounded; SMIL interpolates the parameters linearly, so the *played* transform
between keys is not the fitted one.

Why the bound still holds: the residual each path encodes is measured against the played transforms, not the
fitted ones: local = B_played(t)^-1 H_played(t)^-1 (exact(t)). Whatever the transform keyframing and rounding
leave out becomes residual motion, which the error-bounded encoder keeps within a local radius r_local. The
composed error is |L(t) (local_played - local_exact)| <= sigma_max(L(t)) r_local with L the product of the
linear parts, so r_local = r_global / max_t sigma_max(L(t)) keeps the final position within the global radius.

Painter's order: triangles are drawn back to front across bands (the eyes sit between the skin of the socket
and the eyelids), so one <g> per band would break the order. Paths are grouped in *runs* of consecutive
same-band paths, each run its own <g> with (a copy of) the band's transform animation. ``reorder`` first moves
paths past each other where that cannot change a pixel (``overlap_pairs``: they never come near each other in
a frame where both are drawn), greedily continuing the current band, which merges many runs; ``plan`` then
wraps only the runs whose saved keys outweigh the text of their transform stack, and leaves the others in the
head's frame. When even the head group does not pay for itself, nothing is grouped.

Degenerate motion: a band whose played transform shrinks some direction below MIN_SCALE in some frame (a part
scaled to zero by its joint, collapsed to a line, or fitted to nothing) has no usable inverse, so its runs are
never wrapped and its paths are keyed in the head's frame; a degenerate head is no head transform (identity).

This module knows numbers and error budgets only: ``plan`` returns which runs to wrap and the played transforms,
and the writer (converter.writers.svg_transforms) writes the markup. What text costs, the writer tells it
through ``Costs``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.cluster.vq import kmeans2
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import LinearOperator, eigsh

from converter import heap
from converter.arrays import lengths, unique_ints
from converter.encode import collapse, freeknots
from converter.encode import keys as keyframes
from converter.encode.budget import ErrorBudget
from converter.encode.order import greedy_order
from converter.encode.overlap import overlap_pairs
from converter.encode.robust_affine import fit_affine
from converter.encode.tracks import Tracks, blocks, first_use
from converter.options import Progress, no_progress, span

HEAD_CLUSTERS = 24  # motion clusters of the largest band (the head)
CLUSTER_MIN_TRIANGLES = 50  # fewer clusters on small heads: at least this many triangles each
CLUSTER_COMPONENTS = 12  # principal components of the residual trajectories the clustering uses
CLUSTER_PLACE_WEIGHT = 0.5  # weight of the neutral position against the motion features (keeps clusters compact)
FRAME_BLOCK = 64  # frames a block where a (T, V, 2) temporary is worked a block of frames at a time
MIN_BAND_TRIANGLES = 12  # smaller connected pieces join their part's largest piece
SMALL_BAND_TRIANGLES, SMALL_BAND_SHARE = 100, 0.02  # pieces below max(these) never get a band of their own
NO_LIMIT = np.iinfo(np.int64).max  # freeknots' limit for a track that never stops early
# A path of a run that may pay stops its head-local keys at (1 + STOP_SLACK) its band-local keys plus STOP_SHARE
# times its share of the keys the run must save. Tighter stops sooner but proves fewer runs: on the 128k-triangle
# bench face (0, 1) redid a large share of the paths, (0.2, 1.5) few.
STOP_SLACK, STOP_SHARE = 0.2, 1.5
MERGE_PX = 1.5  # a piece whose motion a larger band explains this well (px, 95th percentile) joins it
HEAD_SHARE = 0.1  # px the head transform's keyframing may leave to the residual, as a share of the tolerance
BAND_SHARE = 0.3  # the same for each band's transform inside the head's (smooth there, and repeated per run)
EVERY_FRAME_SHARE = 0.8  # when keyframing keeps more frames than this share, write every frame (no keyTimes)
PLAIN_SAMPLE = 4  # the plain key count that decides whether groups pay is estimated on every 16th path, then
PLAIN_MARGIN = 0.25  # on every 4th when the first estimate is within this share of the grouped cost
PLAN_SHARES = (0.3, 0.75)  # where plan's layout ends and its decision ends, as fractions of its time (wall, as
# timed on the capture-like face, 8k x 1,000 and the ICT head x 1,000)
TIME_DECIMALS = 4  # keyTimes of the transform animations are played (and so written) rounded to these decimals
# A played transform shrinking some direction below this (viewport px per local px) in a frame is degenerate: its
# inverse would blow local coordinates up past the float error budget (and is singular at 0). The goldens' and the
# rigid tests' bands stay above 0.1.
MIN_SCALE = 0.05


class TransformAnim(NamedTuple):
    """One <animateTransform>: its type, key frames (0..T), rounded values (K, d) and their decimals."""

    kind: str
    frames: np.ndarray  # int (K,) frames of the keys, 0..T (T = loop end)
    values: np.ndarray  # float64 (K, d) as written (translate in viewBox units), rounded to `decimals`
    decimals: int


class BandMotion(NamedTuple):
    """The played transform of one band: its animations and the matrices they give at every frame."""

    centroid: np.ndarray  # (2,) px, the origin of the band's local coordinates
    anims: tuple[TransformAnim, ...]
    matrices: np.ndarray  # float64 (T, 2, 3) local px -> viewport px, as the browser plays it at frame times
    gain: float  # max over frames of the largest singular value of the linear part (local -> global error)
    time_decimals: int  # keyTimes (fractions of the loop) are rounded to these decimals, as the matrices play them


class Costs(NamedTuple):
    """Bytes the writer's syntax spends on what the planner weighs: a group with its transform stack opened, a
    group closed, one path key. The planner wraps a run in a group only where the keys it saves pay for it."""

    transform: Callable[[BandMotion], int]
    close: int
    key: float


class Layout(NamedTuple):
    """Paths regrouped for rigid factoring: draw order, band per path, runs, local tracks and their gains."""

    order: np.ndarray  # int (P,) permutation of the input paths (document order after reordering)
    band: np.ndarray  # int (P,) band of each path, in the new order
    runs: np.ndarray  # int (R + 1,) start of each run of same-band paths, then P
    motions: tuple[BandMotion, ...]  # per band
    gain: np.ndarray  # float64 (P,) error gain of each path's band, head transform included
    head: BandMotion  # the head's transform: the outermost group, around every path
    head_local: Tracks  # float32 path vertices in the head's local px (their own rows: only the paths' vertices,
    # in the order the paths first use them)

    def band_local(self, sel: np.ndarray) -> np.ndarray:
        """Paths sel's vertices (T, len(sel), 6) in their band's local px (relative to its centroid), worked out
        for the paths asked (a whole (T, P, 6) copy would double the plan's memory)."""
        head = self.head_local
        t = head.shape[0]
        out = np.empty((t, len(sel), 6))
        band = self.band[sel]
        for b in np.unique(band).tolist():
            at = np.flatnonzero(band == b)
            # Each vertex once (a vertex is a corner of ~6 paths), as Layout.tracks works them out
            verts, inv = np.unique(head.corners[sel[at]], return_inverse=True)
            pts = local_tracks(np.take(head.verts, verts, axis=1)[:, :, None, :], self.motions[b].matrices)[:, :, 0]
            out[:, at] = np.take(pts, inv.reshape(len(at), 3), axis=1).reshape(t, len(at), 6)
        return out

    def tracks(self, wrapped_runs: list[tuple[int, int]]) -> Tracks:
        """The paths' tracks as encoded: band-local (float32) in the runs wrapped in their band's group, head-local
        elsewhere; one row per vertex and frame of reference, only those some path uses."""
        p = len(self.order)
        frame = np.full(p, -1)  # -1: the head's frame, else the band
        for a, b in wrapped_runs:
            frame[a:b] = self.band[a]
        head = self.head_local
        uses = [(f, np.flatnonzero(frame == f)) for f in np.unique(frame).tolist()]
        uses = [(f, sel, *np.unique(head.corners[sel], return_inverse=True)) for f, sel in uses]
        out = np.empty((head.verts.shape[0], sum(len(v) for _, _, v, _ in uses), 2), np.float32)
        corners = np.empty((p, 3), np.int64)
        at = 0
        for f, sel, verts, inv in uses:
            pts = np.take(head.verts, verts, axis=1)
            if f >= 0:
                pts = local_tracks(pts[:, :, None, :], self.motions[f].matrices)[:, :, 0]
            out[:, at:at + len(verts)] = pts
            corners[sel] = at + inv.reshape(len(sel), 3)
            at += len(verts)
        return Tracks(out, corners)


class Plan(NamedTuple):
    """What the bounded encoder needs to write paths under rigid groups (see ``plan``)."""

    order: np.ndarray  # int (P,) new document order of the input paths
    track: Tracks  # float32 px to encode per path: local (in a group) or global (plain)
    radius: np.ndarray  # float64 (P,) Euclidean px the keyframing of each path may use
    groups: np.ndarray  # int (G, 2) first and one-past-last path (new order) of each run wrapped in its band's group
    band: np.ndarray  # int (P,) band of each path in the new order, -1 when plain (no group)
    gain: np.ndarray  # float64 (P,) local -> global error gain of each path (1 when plain)
    motions: tuple[BandMotion, ...]  # per band: the played transform
    stats: dict[str, float]
    timeline: collapse.Timeline | None  # track's keyframes within radius (freeknots.point_keys), hidden frames
    # folded in (collapse.fold); None without groups
    head: BandMotion | None  # the outermost group's transform, around every path (None: no groups at all)


# --- bands ---------------------------------------------------------------------------------------------------
def components(faces: np.ndarray, part_ids: np.ndarray) -> np.ndarray:
    """Piece id (F,) per triangle: connected pieces of each part (tiny pieces join their part's largest)."""
    f = len(faces)
    n_v = int(faces.max()) + 1
    label = np.zeros(f, np.int64)
    # Triangles sharing a vertex within the same part are connected: a graph on (triangle, vertex) incidences.
    inc = sparse.csr_matrix((np.ones(3 * f), (np.repeat(np.arange(f), 3), faces.reshape(-1))), shape=(f, n_v))
    part_sizes = np.bincount(part_ids)
    next_label = 0
    for p in np.flatnonzero(part_sizes).tolist():
        sel = np.flatnonzero(part_ids == p)
        sub = inc[sel]
        _, comp = connected_components(sub @ sub.T, directed=False)
        sizes = np.bincount(comp)
        comp = np.where(sizes[comp] < MIN_BAND_TRIANGLES, int(np.argmax(sizes)), comp)
        _, comp = np.unique(comp, return_inverse=True)
        label[sel] = next_label + comp
        next_label += int(comp.max()) + 1
    return label


def merge_by_motion(piece: np.ndarray, faces: np.ndarray, xy: np.ndarray, neutral: int,
                    threshold: float, small: int) -> np.ndarray:
    """Band id (F,) per triangle: pieces whose motion a larger band's affine fit explains join that band.

    Pieces are taken largest first. A piece joins the band whose fitted maps move the piece's own vertices
    closest to where they are (95th percentile over frames and vertices) when that is within `threshold` px,
    or in any case when it has fewer than `small` triangles (a band of its own would cost more than it saves).
    Lashes ride on the skin and upper teeth on the head, while the eyeballs, which rotate in their sockets,
    keep their own bands."""
    ids, sizes = np.unique(piece, return_counts=True)
    bands: list[tuple[int, np.ndarray, np.ndarray]] = []  # (band label, its fit (T, 2, 3), its centre)
    out = piece.copy()
    rank = np.argsort(-sizes, kind="stable")
    for pid, size in zip(ids[rank].tolist(), sizes[rank].tolist()):
        verts = unique_ints(faces[piece == pid])
        ref = xy[neutral, verts]
        errors = []
        for _, fit, centre in bands:
            pred = apply_linear(fit[:, :, :2], ref - centre) + fit[:, None, :, 2]
            errors.append(np.percentile(lengths(pred - np.take(xy, verts, axis=1)), 95))
        if errors and (min(errors) <= threshold or size < small):
            out[piece == pid] = bands[int(np.argmin(errors))][0]
            continue
        centre = ref.mean(axis=0)
        bands.append((pid, fit_affine(ref - centre, xy, verts), centre))
    return out


def motion_clusters(band: np.ndarray, faces: np.ndarray, xy: np.ndarray, neutral: int, clusters: int) -> np.ndarray:
    """Band id (F,) with the largest band (the head) cut into up to `clusters` bands that move alike on screen.

    The head's own affine fit leaves, per vertex, a residual trajectory: depth parallax of the turning head and
    expression (brows, jaw, cheeks). Triangles are clustered (k-means, seeded) on the leading principal
    components of their vertices' residual trajectories, plus a little of their neutral position so that
    clusters stay compact; each cluster then gets its own affine fit, which absorbs its share of that motion."""
    ids, sizes = np.unique(band, return_counts=True)
    big = ids[np.argmax(sizes)]
    sel = np.flatnonzero(band == big)
    out = band * (clusters + 1)  # room for the cluster ids
    k = min(clusters, len(sel) // CLUSTER_MIN_TRIANGLES)
    if k < 2:
        return out
    verts, pos = np.unique(faces[sel], return_inverse=True)
    ref = xy[neutral, verts]
    center = ref.mean(axis=0)
    fit = fit_affine(ref - center, xy, verts)
    rel, t = ref - center, len(xy)
    # buffers for a block of frames, reused: fresh pages cost system time to fault in
    bufs = [np.empty((min(t, FRAME_BLOCK), len(verts), 2)) for _ in range(2)]

    def residuals():  # per block of frames, the vertices' residuals (a view of a buffer: used before the next)
        for sl in blocks(t, FRAME_BLOCK):
            part = np.take(xy[sl], verts, axis=1, out=bufs[0][:sl.stop - sl.start])
            model = apply_linear(fit[sl, :, :2], rel, out=bufs[1][:sl.stop - sl.start])
            model += fit[sl, None, :, 2]
            part -= model
            yield sl, part

    # Worked out a block of frames at a time, three times over (their mean, their spread about it, then the
    # features), rather than held: the residuals (T, n, 2), their lengths and then a transposed copy for the
    # features were the peak of a long capture (the ICT head x 4,000: BENCHMARKS.md, conversion speed and memory).
    total = np.zeros((len(verts), 2))  # the residuals' sum over frames, added frame by frame as .sum(axis=0) adds
    for _, part in residuals():
        for f in range(len(part)):  # (no loop name left holding a view of the buffer)
            total += part[f]
    mean = total / max(t, 1)
    spread = np.empty((len(verts), t))
    for sl, part in residuals():
        spread[:, sl] = lengths(part - mean).T
    del mean
    if np.percentile(spread, 95, overwrite_input=True) <= MERGE_PX:  # (partitioned in place, not in a copy)
        return out  # the head moves rigidly: one band explains it
    del spread
    res = np.empty((len(verts), t, 2))  # per vertex its residual trajectory: the features' layout
    for sl, part in residuals():
        res[:, sl] = part.transpose(1, 0, 2)
    part = bufs = None  # the block buffers go (part is a view of one)
    feat = res.reshape(len(verts), -1)  # vertex v's frame k coordinate c at column 2k + c
    del res
    feat -= feat.mean(axis=0)
    feat = principal_components(feat, CLUSTER_COMPONENTS)
    place = (ref - center) / max(float((ref - center).std()), 1e-9) * float(feat.std()) * CLUSTER_PLACE_WEIGHT
    tri_feat = np.c_[feat, place][pos.reshape(-1, 3)].mean(axis=1)
    _, label = kmeans2(tri_feat, k, seed=np.random.default_rng(0), minit="++")
    out[sel] += label
    return out


def principal_components(feat: np.ndarray, k: int) -> np.ndarray:
    """Coordinates (n, k) of the rows of centred feat (n, m) on its k leading principal axes (u s of the SVD).

    Only the k leading axes are needed: Lanczos (ARPACK, fixed start vector, so deterministic) on feat^T feat
    costs a few products with feat, where a full SVD costs n m^2."""
    n, m = feat.shape
    if k >= min(n, m) - 1:
        u, sv, _ = np.linalg.svd(feat, full_matrices=False)
        return u[:, :k] * sv[:k]
    op = LinearOperator((m, m), matvec=lambda x: feat.T @ (feat @ x), dtype=np.float64)
    _, axes = eigsh(op, k=k, v0=np.ones(m))
    return feat @ axes[:, ::-1]


# --- affine fits and the transform stack -----------------------------------------------------------------------
def apply_linear(lin: np.ndarray, pts: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Per frame t the 2x2 map lin[t] (T, 2, 2) applied to the points pts[t] (T, ..., 2), or to the same points
    pts (N, 2) in every frame -> (T, N, 2); into out (contiguous, pts' shape or (T, N, 2)) when given. A matrix
    product: einsum takes far longer on (T, P, 3, 2) tracks."""
    lin_t = np.swapaxes(lin, 1, 2)
    if pts.ndim == 2:
        return np.matmul(pts[None], lin_t, out=out)
    t = pts.shape[0]
    flat = None if out is None else out.reshape(t, -1, 2)
    return np.matmul(pts.reshape(t, -1, 2), lin_t, out=flat).reshape(pts.shape)


def decompose(a: np.ndarray, center: np.ndarray) -> np.ndarray:
    """(T, 2, 3) affine maps -> (T, 6) parameters tx ty (image of center) angle skew (degrees) sx sy."""
    lin = a[:, :, :2]
    theta = np.unwrap(np.arctan2(lin[:, 1, 0], lin[:, 0, 0]))
    c, s = np.cos(theta), np.sin(theta)
    sx = np.hypot(lin[:, 0, 0], lin[:, 1, 0])
    u01 = c * lin[:, 0, 1] + s * lin[:, 1, 1]  # R^T L = [[sx, sy tan k], [0, sy]]
    sy = -s * lin[:, 0, 1] + c * lin[:, 1, 1]
    safe = np.abs(sy) > 1e-9
    skew = np.where(safe, np.arctan(u01 / np.where(safe, sy, 1.0)), np.arctan2(u01, sy))
    trans = np.einsum("tij,j->ti", lin, center) + a[:, :, 2]
    return np.column_stack([trans, np.degrees(theta), np.degrees(skew), sx, sy])


def compose(params: np.ndarray, center: np.ndarray) -> np.ndarray:
    """(T, 6) parameters -> (T, 2, 3) maps translate . rotate . skewX . scale, taking points relative to center."""
    theta, skew = np.radians(params[:, 2]), np.radians(params[:, 3])
    c, s = np.cos(theta), np.sin(theta)
    sx, sy = params[:, 4], params[:, 5]
    u = np.zeros((len(params), 2, 2))
    u[:, 0, 0], u[:, 0, 1], u[:, 1, 1] = sx, sy * np.tan(skew), sy
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], 1)
    out = np.zeros((len(params), 2, 3))
    out[:, :, :2] = rot @ u
    out[:, :, 2] = params[:, :2] - np.einsum("tij,j->ti", out[:, :, :2], center)
    return out


def _decimals(step: float) -> int:
    """Fewest decimals whose rounding (half a unit) stays within step."""
    return int(np.clip(math.ceil(-math.log10(max(2 * step, 1e-12))), 0, 8))


STACK = {"translate": [0, 1], "rotate": [2], "skewX": [3], "scale": [4, 5]}  # parameter columns of each transform


def _param_eps(radius: float, slack: float) -> np.ndarray:
    """Per-parameter bound (6,) so each moves a point of a band of this radius by at most slack / 4 px."""
    radius = max(radius, 1.0)
    per = slack / 4
    return np.array([per, per, math.degrees(per / radius), math.degrees(per / radius), per / radius, per / radius])


def _param_tracks(params: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """(T, 4, 2) parameter groups of the transform stack in units of their bound (1-D ones padded with 0)."""
    tracks = np.zeros((len(params), len(STACK), 2))
    for i, cols in enumerate(STACK.values()):
        tracks[:, i, :len(cols)] = params[:, cols] / eps[cols]
    return tracks


def band_motion(params: np.ndarray, center: np.ndarray, radius: float, slack: float, scale: int,
                kt_decimals: int = TIME_DECIMALS, keys: keyframes.Keys | None = None) -> BandMotion:
    """Keyframed, rounded transform stack for fitted parameters (T, 6) about center; radius: band extent px;
    slack: px the keyframing may leave to the residual; translate is kept in units of 1/scale px. keys: the
    parameter groups' keys (``keys.reduce`` of ``_param_tracks`` within 1) when already worked out."""
    t = len(params)
    eps = _param_eps(radius, slack)
    radius = max(radius, 1.0)
    # Rounding of the written values: small against the slack so the residual does not pick up rounding noise.
    r = slack / 4
    rounding = {"translate": r, "rotate": math.degrees(r / radius), "skewX": math.degrees(r / radius),
                "scale": r / radius}
    identity = np.array([0, 0, 0, 0, 1, 1.0])
    groups = STACK
    anims = []
    played = np.tile(identity, (t, 1))
    frames_t = np.arange(t)
    q = 10 ** kt_decimals
    if keys is None:  # every parameter group keyed in one pass
        keys = keyframes.reduce(_param_tracks(params, eps), np.ones((t, len(groups)), bool), 1.0)
    for i, (kind, cols) in enumerate(groups.items()):
        x = params[:, cols]
        if kind != "translate" and np.abs(x - identity[cols]).max() <= eps[cols[0]]:
            continue  # the identity explains it: no animation
        kf = np.flatnonzero(keys.mask[:, i])
        unit = scale if kind == "translate" else 1.0  # translate is written in viewBox units
        dec = _decimals(rounding[kind] * unit)
        if len(kf) > EVERY_FRAME_SHARE * (t + 1):  # jitter keeps nearly every frame: all, without keyTimes
            kf = np.arange(t + 1)
            vals = np.round(np.vstack([x, x[-1:]]) * unit, dec)
        else:
            vals = np.round(keys.values[kf, i, :len(cols)] * eps[cols] * unit, dec)
        if len(kf) == 2 and np.array_equal(vals[0], vals[1]):  # constant: one value plays as a set
            kf, vals = kf[:1], vals[:1]
        kt = kf / t if len(kf) == t + 1 else np.rint(kf * q / t) / q  # every frame: no keyTimes written
        for c, col in enumerate(cols):
            played[:, col] = (np.interp(frames_t / t, kt, vals[:, c]) if len(kf) > 1 else vals[0, c]) / unit
        anims.append(TransformAnim(kind, kf, vals, dec))
    mats = compose(played, np.zeros(2))
    gain = float(np.linalg.svd(mats[:, :, :2], compute_uv=False).max()) if t else 1.0
    return BandMotion(np.asarray(center, np.float64), tuple(anims), mats, gain, kt_decimals)


def invertible(mats: np.ndarray) -> bool:
    """Whether played transforms mats (T, 2, 3) are finite and keep every direction at least MIN_SCALE long in
    every frame (the smaller singular value of each linear part), so that local coordinates stay bounded."""
    if not np.isfinite(mats).all():
        return False
    lin = mats[:, :, :2].reshape(-1, 4)
    det = np.abs(lin[:, 0] * lin[:, 3] - lin[:, 1] * lin[:, 2])
    sq = np.einsum("ti,ti->t", lin, lin)  # s_max^2 + s_min^2; and s_max s_min = |det|
    s_max = np.sqrt((sq + np.sqrt(np.maximum(sq * sq - 4 * det * det, 0.0))) / 2)
    return bool(((det > 0) & (det >= MIN_SCALE * s_max)).all())  # s_min = det / s_max >= MIN_SCALE


def identity_motion(t: int, kt_decimals: int = TIME_DECIMALS) -> BandMotion:
    """No transform over t frames: local px are viewport px (what a degenerate head falls back to)."""
    mats = np.zeros((t, 2, 3))
    mats[:, 0, 0] = mats[:, 1, 1] = 1.0
    return BandMotion(np.zeros(2), (), mats, 1.0, kt_decimals)


def local_tracks(xy_paths: np.ndarray, mats: np.ndarray) -> np.ndarray:
    """Path vertices (T, P, 3, 2) px -> local px of one band's played transforms mats (T, 2, 3), which must be
    ``invertible`` (the planner never wraps a path in a degenerate band's group)."""
    if not invertible(mats):
        raise ValueError("local tracks of a degenerate transform (a frame's linear part is singular or nearly so)")
    return apply_linear(np.linalg.inv(mats[:, :, :2]), xy_paths - mats[:, None, None, :, 2])


# --- drawing order ----------------------------------------------------------------------------------------------
def reorder(band: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """A draw order (permutation) keeping every pair's order and each band's own order, continuing the current
    band greedily (switching to the band whose next path comes earliest)."""
    p = len(band)
    # Each band's paths stay in their order: chain each to the next path of its band.
    by_band = np.lexsort((np.arange(p), band))
    same = band[by_band[1:]] == band[by_band[:-1]]
    chain = np.column_stack([by_band[:-1][same], by_band[1:][same]])
    return greedy_order(band, np.concatenate([np.asarray(pairs, np.int64).reshape(-1, 2), chain]),
                        lambda free: min((h[0], b) for b, h in free.items() if h)[1])


# --- layout and plan --------------------------------------------------------------------------------------------
def layout(xy: np.ndarray, faces: np.ndarray, part_ids: np.ndarray, neutral: int,
           tris: np.ndarray, active: np.ndarray, budget: ErrorBudget, kt_decimals: int = TIME_DECIMALS,
           head_clusters: int = HEAD_CLUSTERS, merge_runs: bool = True,
           progress: Progress = no_progress) -> Layout:
    """Head motion, bands, played transforms, run order and local tracks for paths tris (P,) shown where
    active (T, P). progress(stage, fraction of the layout done) between its steps (shares measured on the ICT
    head x 1,000 and the capture-like face: the overlap search is its largest step).

    xy (T, V, 2) px comes from the Sheet; budget.tolerance px is the global bound the residual encoder works to
    (the transforms take HEAD_SHARE and BAND_SHARE of it as fitting slack, not as error). The head's transform is
    fitted on the screen positions and keyed tightly (it carries the capture's pose jitter, every frame, once
    for the whole document); each band's transform is fitted in the head's frame, where what is left is
    smooth, and keyed loosely, since every run of the band repeats it."""
    t = xy.shape[0]
    tolerance, scale = budget.tolerance, budget.scale
    xy64 = xy.astype(np.float64)
    small = max(SMALL_BAND_TRIANGLES, int(SMALL_BAND_SHARE * len(faces)))
    progress("motion", 0.0)
    merged = merge_by_motion(components(faces, part_ids), faces, xy64, neutral, MERGE_PX, small)
    progress("motion", 0.12)
    ids, sizes = np.unique(merged, return_counts=True)
    head = _motion(xy64, unique_ints(faces[merged == ids[np.argmax(sizes)]]), neutral, HEAD_SHARE * tolerance,
                   scale, kt_decimals)
    if not invertible(head.matrices):  # e.g. the skin scaled to nothing in a frame: no head transform
        head = identity_motion(t, kt_decimals)
    # local_tracks, worked in xy64's place a block of frames at a time (xy64 is not needed after this): a second
    # (T, V, 2) float64 array is fresh pages for the kernel to zero (with motion_clusters' blocks, this cut the
    # system CPU of layout, apply_linear and motion_clusters on the 128k-triangle bench face)
    in_head = xy64  # head frame px, about its centroid; the rest works in it (and the overlap test on the float32 xy)
    del xy64
    inv = np.linalg.inv(head.matrices[:, :, :2])
    buf = np.empty((min(t, FRAME_BLOCK),) + in_head.shape[1:])
    for sl in blocks(t, FRAME_BLOCK):  # no name is left holding a view: it would keep the float64 array alive
        in_head[sl] -= head.matrices[sl, None, :, 2]
        in_head[sl] = apply_linear(inv[sl], in_head[sl], out=buf[:sl.stop - sl.start])
    del buf
    progress("motion", 0.25)
    band_of_tri = motion_clusters(merged, faces, in_head, neutral, head_clusters)
    band_ids, band = np.unique(band_of_tri[tris], return_inverse=True)
    progress("motion", 0.42)
    motions = _motions(in_head, [unique_ints(faces[band_of_tri == b]) for b in band_ids.tolist()], neutral,
                       BAND_SHARE * tolerance, scale, kt_decimals)
    progress("motion", 0.5)
    # Stored as float32: ~1e-5 px at these magnitudes (budget.float_err), half the plan's largest array; and only
    # the vertices of the paths tris (on the ICT head well under all: the others' triangles are never seen)
    rows = unique_ints(faces[tris])
    local = np.empty((t, len(rows), 2), np.float32)
    for sl in blocks(t, FRAME_BLOCK):
        local[sl] = np.take(in_head[sl], rows, axis=1)
    del in_head
    row_of = np.full(xy.shape[1], -1, np.int64)
    row_of[rows] = np.arange(len(rows))
    order = np.arange(len(tris))
    if merge_runs and len(tris) > 1:
        order = reorder(band, overlap_pairs(xy, active, band=band, corners=faces[tris], drift=head.matrices[:, :, 2],
                                            progress=span(progress, 0.5, 0.98)))
    band = band[order]
    # Rows renumbered in the order the paths first use them: a block of paths then gathers its tracks from nearby
    # rows of each frame (a faster pass over every path on the ICT head x 1,000; the plan makes several)
    corners = row_of[faces[tris[order]]]
    along = first_use(corners, len(rows))
    for sl in blocks(t, FRAME_BLOCK):
        local[sl] = np.take(local[sl], along, axis=1)
    renumber = np.empty(len(rows), np.int64)
    renumber[along] = np.arange(len(rows))
    gains = np.zeros(len(band_ids))
    for b, m in enumerate(motions):
        lin = np.einsum("tij,tjk->tik", head.matrices[:, :, :2], m.matrices[:, :, :2])
        gains[b] = float(np.linalg.svd(lin, compute_uv=False).max()) if t else 1.0
    change = np.flatnonzero(np.diff(band)) + 1
    runs = np.concatenate([[0], change, [len(tris)]]).astype(np.int64)
    return Layout(order, band, runs, tuple(motions), gains[band], head, Tracks(local, renumber[corners]))


def _motion(xy: np.ndarray, verts: np.ndarray, neutral: int, slack: float, scale: int,
            kt_decimals: int) -> BandMotion:
    """The played transform of the vertices verts of xy (T, V, 2), fitted from the neutral frame."""
    return _motions(xy, [verts], neutral, slack, scale, kt_decimals)[0]


def _motions(xy: np.ndarray, vert_sets: list[np.ndarray], neutral: int, slack: float, scale: int,
             kt_decimals: int) -> list[BandMotion]:
    """_motion of each vertex set, their transform parameters keyed in one pass (tracks are independent)."""
    fits = []
    for verts in vert_sets:
        ref = xy[neutral, verts]
        center = ref.mean(axis=0)
        radius = float(np.linalg.norm(ref - center, axis=1).max()) if len(verts) else 1.0
        fits.append((decompose(fit_affine(ref - center, xy, verts), np.zeros(2)), center, radius))
    if not fits:
        return []
    t, g = xy.shape[0], len(STACK)
    tracks = np.concatenate([_param_tracks(p, _param_eps(r, slack)) for p, _, r in fits], axis=1)
    keys = keyframes.reduce(tracks, np.ones((t, tracks.shape[1]), bool), 1.0)
    return [band_motion(p, c, r, slack, scale, kt_decimals,
                        keyframes.Keys(keys.mask[:, i * g:(i + 1) * g], keys.values[:, i * g:(i + 1) * g],
                                       keys.first_active[i * g:(i + 1) * g]))
            for i, (p, c, r) in enumerate(fits)]


def plan(xy: np.ndarray, faces: np.ndarray, part_ids: np.ndarray, neutral: int, tris: np.ndarray,
         active: np.ndarray, budget: ErrorBudget, costs: Costs, head_clusters: int = HEAD_CLUSTERS,
         merge_runs: bool = True, progress: Progress = no_progress) -> Plan:
    """Rigid layout for the bounded encoder: the head group around everything, which runs of paths go under a
    band's group inside it, and their tracks.

    A run is wrapped only when the keys it saves (band-local against head-local keyframe counts, at costs.key
    bytes each) outweigh its group (costs.transform of its band plus costs.close); the other paths sit in the
    head's frame. When even that costs more than the plain encoding (global keys), nothing is grouped.
    Band-local tracks and keys are worked out a block of runs at a time and kept only where they win, so the
    plan holds one track and one set of keys per path: the tracks once per vertex (encode.tracks), the square
    keys packed (keys.Packed) until the other shapes refine them and collapse folds them, a block of paths at a
    time, into the timeline the writer keys from.

    progress(stage, fraction of the plan done): the layout, the decision's blocks of runs and the refining's blocks
    of paths take about PLAN_SHARES of it."""
    t, p = active.shape
    lay = layout(xy, faces, part_ids, neutral, tris, active, budget, head_clusters=head_clusters,
                 merge_runs=merge_runs, progress=span(progress, 0.0, PLAN_SHARES[0]))
    decided = span(progress, PLAN_SHARES[0], PLAN_SHARES[1], "groups")
    act = np.take(active, lay.order, axis=1)
    global_radius = budget.keys
    r_local = budget.local_keys(lay.gain)
    r_head = float(budget.local_keys(np.array([lay.head.gain]))[0])
    ok = r_local > 0.05 * global_radius  # a band that magnifies errors too much is not worth it
    ok &= np.array([invertible(m.matrices) for m in lay.motions], bool)[lay.band]  # degenerate bands: never wrapped

    def keys_of(x, r, cols, limit=None):
        # Squares only: which paths to wrap is decided on these; the other shapes refine the chosen tracks below.
        radii = np.broadcast_to(np.maximum(r, 1e-6), (p,))[cols]
        return freeknots.shape_keys(x, np.take(act, cols, axis=1), radii, freeknots.SHAPES_DEG[0], limit)

    size = freeknots.block_tracks(t)

    def packed_keys(tracks_of, r, paths: np.ndarray,
                    limit: np.ndarray | None = None) -> tuple[keyframes.Packed, np.ndarray]:
        # a block of paths at a time: their tracks (float64 when band-local) and dense keys stay small. A long run
        # is a block of runs of its own; at once, its tracks alone are 48 B per path and frame (GBs at 4,000 frames)
        parts, gave_up = [], np.zeros(len(paths), bool)
        for sl in blocks(len(paths), size):
            k, gave_up[sl] = keys_of(tracks_of(paths[sl]), r, paths[sl], None if limit is None else limit[sl])
            parts.append(keyframes.pack(k))
        return keyframes.join(parts), gave_up

    def head_keys_of(paths: np.ndarray, limit: np.ndarray | None = None) -> tuple[keyframes.Packed, np.ndarray]:
        return packed_keys(lay.head_local.take, r_head, paths, limit)

    group_bytes = [costs.transform(m) for m in lay.motions]
    runs = list(zip(lay.runs[:-1].tolist(), lay.runs[1:].tolist()))

    def pays(a: int, saved_bytes: float) -> bool:  # wrapping run a..: its band's group, once more
        return bool(ok[a]) and saved_bytes > group_bytes[int(lay.band[a])] + costs.close

    def wraps(a: int, b: int, kh: np.ndarray) -> bool:  # at most its head-local keys kh, and what it saves, pay
        return pays(a, kh.sum() * costs.key) and pays(a, ((kh - kl_n[a:b]) * costs.key).sum())

    # Band-local keys first, then head-local ones: a path of a run that may pay stops its head-local keys once it
    # needs STOP_SLACK more than its band-local keys and STOP_SHARE times its share of the group's cost (freeknots'
    # limit). Where those lower bounds already make the run pay, their full counts are not needed (wrapped paths:
    # their head-local keys far outnumbered the band-local ones on the 128k-triangle bench face); in the other runs the
    # paths that stopped are redone. The groups, keys and counts are those of every head-local track in full.
    kh_n, kl_n = np.zeros(p, np.int64), np.zeros(p, np.int64)
    head_parts: list[keyframes.Packed] = []
    wrapped_runs: list[tuple[int, int]] = []
    local_keys: dict[int, keyframes.Packed] = {}  # first path of a wrapped run -> its band-local keys
    wrapped = np.zeros(p, bool)
    for block in _run_blocks([(a, b) for a, b in runs if b > a], size):
        lo, hi = block[0][0], block[-1][1]
        decided("groups", lo / p)
        cand = [(a, b) for a, b in block if ok[a]]
        limit = np.full(hi - lo, NO_LIMIT, np.int64)
        kl = None
        if cand:
            sel = np.concatenate([np.arange(a, b) for a, b in cand])
            kl = packed_keys(lay.band_local, r_local, sel)[0]
            kl_n[sel] = np.diff(kl.start)
            for a, b in cand:
                share = int((group_bytes[int(lay.band[a])] + costs.close) / costs.key // (b - a)) + 1
                limit[a - lo:b - lo] = (np.floor(kl_n[a:b] * (1 + STOP_SLACK)).astype(np.int64)
                                        + max(int(STOP_SHARE * share), 1))
        kh, gave_up = head_keys_of(np.arange(lo, hi), limit)
        kh_n[lo:hi] = np.where(gave_up, limit, np.diff(kh.start))  # at least, where they stopped
        redo = [np.arange(a, b)[gave_up[a - lo:b - lo]] for a, b in cand
                if gave_up[a - lo:b - lo].any() and not wraps(a, b, kh_n[a:b])]
        if redo:
            again = np.concatenate(redo)
            exact, _ = head_keys_of(again)
            kh = keyframes.replace(kh, again - lo, exact)
            kh_n[again] = np.diff(exact.start)
        at, chosen = 0, []
        for a, b in cand:
            if wraps(a, b, kh_n[a:b]):
                wrapped_runs.append((a, b))
                wrapped[a:b] = True
                chosen.append((a, b, at))
            at += b - a
        # Each path keeps one set of keys: band-local where wrapped, else head-local (copies, so that the block's
        # arrays of the other set go)
        head_parts.append(keyframes.emptied(kh, np.flatnonzero(wrapped[lo:hi])))
        if chosen:
            kl = keyframes.emptied(kl, np.flatnonzero(~wrapped[sel]))
            for a, b, at in chosen:
                local_keys[a] = kl.part(at, at + b - a)
        del kl, kh
    head_keys = keyframes.join(head_parts)  # p >= 1 (svg_anim plans only paths it draws): one block at least
    head_bytes = costs.transform(lay.head)
    n_keys = np.where(wrapped, kl_n, kh_n)
    transform_bytes = head_bytes + sum(group_bytes[int(lay.band[a])] for a, _ in wrapped_runs)
    grouped_cost = int(n_keys.sum()) * costs.key + transform_bytes
    plain_keys = _plain_keys(xy, faces, tris[lay.order], act, global_radius, grouped_cost / costs.key)
    stats = {"bands": len(lay.motions), "runs": len(lay.runs) - 1, "groups": len(wrapped_runs),
             "grouped_paths": int(wrapped.sum()), "keys_global": plain_keys,
             "max_gain": float(max(lay.gain.max(), lay.head.gain)) if p else 1.0}
    if grouped_cost >= plain_keys * costs.key:  # the plain encoding is shorter: no groups
        stats.update(groups=0, grouped_paths=0, transform_bytes=0, keys_rigid=plain_keys)
        return Plan(lay.order, Tracks.screen(xy, faces[tris[lay.order]]), np.full(p, global_radius),
                    np.zeros((0, 2), np.int64), np.full(p, -1),
                    np.ones(p), lay.motions, stats, None, None)
    stats.update(transform_bytes=transform_bytes, keys_rigid=int(n_keys.sum()))
    track = lay.tracks(wrapped_runs)
    lay = lay._replace(head_local=None)
    radius = np.where(wrapped, r_local, r_head)
    band = np.where(wrapped, lay.band, -1)
    gain = np.where(wrapped, lay.gain, lay.head.gain)
    starts = np.array([a for a, _ in wrapped_runs], np.int64)

    def best_keys(a: int, b: int) -> keyframes.Keys:  # the squares (band-local where wrapped), refined
        k = head_keys.unpack(a, b)
        for i in range(max(int(np.searchsorted(starts, a, "right")) - 1, 0), int(np.searchsorted(starts, b))):
            ra, rb = wrapped_runs[i]
            lo, hi = max(a, ra), min(b, rb)
            if lo < hi:
                part = local_keys[ra].unpack(lo - ra, hi - ra)
                k.mask[:, lo - a:hi - a], k.values[:, lo - a:hi - a] = part.mask, part.values
        if len(freeknots.SHAPES_DEG) > 1:
            k = freeknots.point_keys(track.take(slice(a, b)), act[:, a:b], radius[a:b], freeknots.SHAPES_DEG[1:],
                                     best=k)
        return k._replace(values=k.values[..., :6])

    heap.give_back()  # the decision's blocks of tracks and dense keys, before the refining's
    # small blocks: their refining temporaries (dense keys, jitter) come on top of every path's tracks and keys
    timeline = collapse.fold_blocks(act, best_keys, max(16, size // 4), span(progress, PLAN_SHARES[1], 1.0))
    return Plan(lay.order, track, radius, np.array(wrapped_runs, np.int64).reshape(-1, 2), band, gain,
                lay.motions, stats, timeline, lay.head)


def _plain_keys(xy: np.ndarray, faces: np.ndarray, tris: np.ndarray, active: np.ndarray, radius: float,
                grouped_keys: float) -> int:
    """The plain encoding's key count for paths tris (global tracks within radius), which only decides whether
    grouping pays (against grouped_keys, its cost in keys): estimated from every PLAIN_SAMPLE ** 2-th path, then
    from every PLAIN_SAMPLE-th when that estimate is within PLAIN_MARGIN of grouped_keys."""
    p = len(tris)
    steps = [s for s in (PLAIN_SAMPLE ** 2, PLAIN_SAMPLE) if p >= 50 * s] or [1]  # >= 50 paths in a sample
    keys_n = 0
    screen = Tracks.screen(xy, faces[tris])
    size = freeknots.block_tracks(active.shape[0])
    for i, step in enumerate(steps):
        sample = np.arange(0, p, step)
        found = 0
        for sl in blocks(len(sample), size):  # a block of paths at a time: only their count is kept
            plain = freeknots.point_keys(screen.take(sample[sl]), np.take(active, sample[sl], axis=1),
                                         np.full(len(sample[sl]), max(radius, 1e-6)), freeknots.SHAPES_DEG[:1])
            found += int(plain.mask.sum())
        keys_n = int(round(found * p / len(sample)))
        if i == len(steps) - 1 or abs(keys_n - grouped_keys) > PLAIN_MARGIN * grouped_keys:
            break
    return keys_n


def _run_blocks(runs: list[tuple[int, int]], size: int) -> list[list[tuple[int, int]]]:
    """Consecutive runs grouped into blocks of about size paths (a longer run is a block of its own)."""
    blocks: list[list[tuple[int, int]]] = []
    n = size
    for a, b in runs:
        if n + b - a > size:
            blocks.append([])
            n = 0
        blocks[-1].append((a, b))
        n += b - a
    return blocks


def compose_tracks(plan_: Plan, local: np.ndarray) -> np.ndarray:
    """Paths' coordinates (T, P, 6) in their own frames (band or head local) -> viewport px, as played."""
    out = np.array(local, np.float64, copy=True)
    t, p = out.shape[:2]

    def apply(m: BandMotion, sel: np.ndarray) -> None:
        pts = np.take(out, sel, axis=1).reshape(t, len(sel), 3, 2)
        out[:, sel] = (apply_linear(m.matrices[:, :, :2], pts)
                       + m.matrices[:, None, None, :, 2]).reshape(t, len(sel), 6)

    for b, m in enumerate(plan_.motions):
        apply(m, np.flatnonzero(plan_.band == b))
    if plan_.head is not None:
        apply(plan_.head, np.arange(p))
    return out
