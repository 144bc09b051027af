"""Triangle budget (the chapter's section 12.4.2): simplify once, every frame shares the simplified topology.

meshoptimizer's simplifier collapses edges onto existing vertices (half-edge collapse with quadric error), so
the result indexes a subset of the original vertices and the animation carries over by indexing. The quadric
error is extended with motion attributes (meshopt_simplifyWithAttributes): each vertex carries the first
principal components of its displacement over the whole animation, so collapsing a vertex onto one that moves
differently (lips, eyelids, brows) costs error and those regions keep their detail, as the chapter asks.

Each part (skin, eyes, teeth, ...) is simplified on its own with the vertices it shares with other parts
locked, with a share of the budget proportional to its triangles (when that cannot be met, seams are freed and
small disconnected pieces such as single lashes pruned); triangles that never face the camera are dropped first when the
conversion options (camera) are known.

Under the mobile preset (options.BOUNDED_PRESETS) the budget is a bound on what it does to the face, not a count:
each part is simplified as far as options.SIMPLIFY_BOUND allows (its vertices within 0.5 px on average and 5 px at
worst of the simplified surface at the output size, and its pixels at frame 0 kept), at most max_triangles in all;
a part whose pixels another covers (an eyelid over the eye) makes that one keep its vertices there. Either way the
report gives the deviation, each part's pixels kept and whether both are within the bound, with a warning in words
when a part lost visible area.
"""

from __future__ import annotations

import ctypes

import numba
import numpy as np

from converter import raster
from converter.animation import FaceAnimation
from converter.camera import Camera
from converter.errors import InputError
from converter.extract import FRAME_BLOCK, cull, fit_camera
from converter.options import (
    BOUNDED_PRESETS,
    PRESETS,
    SIMPLIFY_BOUND,
    ConversionOptions,
    Progress,
    Report,
    SimplifyBound,
    no_progress,
    span,
)

MOTION_COMPONENTS = 6  # principal components of each vertex's displacement carried as attributes
MOTION_WEIGHT = 4.0  # attribute weight: how much a motion mismatch costs against geometric error
MOTION_FRAMES = 512  # frames the motion attributes read at most: memory and the (3T)^2 eigenproblem stay bounded
# The budget's passes, ms per frame they read on the ICT head (wall, 1,000 and 4,000 frames): which triangles ever
# face the camera and the deviation read every frame, the motion at most MOTION_FRAMES; their progress shares
BUDGET_MS = {"facing": 1.1, "motion": 6.9, "deviation": 1.1}
GRAM_DONE = 0.85  # of the motion pass, where the product m.T m is done and its eigenvectors start (the product is
# the larger part, as timed on the ICT head x 512 frames)
SEARCH_STEPS = 8  # halvings (in log error) of each part's search for the largest error its bound allows
SEARCH_ERRORS = (1e-5, 0.1)  # meshoptimizer's relative error: every part kept whole ... simplified to its bones
# What the search measures is not quite the final mesh's: deviation on PROBE_FRAMES (not every frame), each part's
# pixels among the others whole (together, an eyelid's simplification changes the eye's). So it holds each part to
# this share of the bound's px, and of the pixels a part may lose.
SEARCH_MARGIN = 0.9
COVERAGE_MARGIN = 0.5
FIX_RADIUS = 4  # px around the pixels a part lost to another within which that one's vertices are kept
FIX_ROUNDS, FIX_STEP = 8, 1.5  # then parts that break the bound together: their error divided by FIX_STEP, at most
# FIX_ROUNDS times (and kept whole below the search's least error)
PROBE_FRAMES = 32  # frames the search measures (probe_frames); the report reads every frame
FIT_SHARE = 0.28  # of the facing pass, the camera's fit to every frame (as timed on the ICT head x 2,000 frames)

_P = ctypes.POINTER


def _simplify_with_attributes():
    """meshopt_simplifyWithAttributes with a full ctypes prototype.

    The meshoptimizer 0.2.x Python wrapper calls this C function without argtypes, so its float argument
    cannot be converted (ctypes.ArgumentError) and the size_t result is read as int; we bind the same
    symbol of the bundled library with the C signature instead."""
    from meshoptimizer import simplifier  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    proto = ctypes.CFUNCTYPE(
        ctypes.c_size_t, _P(ctypes.c_uint), _P(ctypes.c_uint), ctypes.c_size_t, _P(ctypes.c_float), ctypes.c_size_t,
        ctypes.c_size_t, _P(ctypes.c_float), ctypes.c_size_t, _P(ctypes.c_float), ctypes.c_size_t, _P(ctypes.c_ubyte),
        ctypes.c_size_t, ctypes.c_float, ctypes.c_uint, _P(ctypes.c_float),
    )
    return proto(("meshopt_simplifyWithAttributes", simplifier.lib))


def rigid_residual(frames: np.ndarray, rounds: int = 3, progress: Progress = no_progress) -> np.ndarray:
    """(T, V, 3): each frame rigidly aligned (Kabsch) onto the first, minus the first: the deformation only.

    The fit is repeated on the half of the vertices that deform least, so a jaw opening does not tilt it.
    Every frame is fitted on its own, a block of frames at a time: compiled passes over its vertices for the
    centroids and cross-covariance, then for the residual and its length (as numpy's weighted sums, products and
    norm they cost several times what the whole fit costs now); the 3x3 SVDs and the medians stay numpy's."""
    ref = np.asarray(frames[0], np.float64)
    # Stored vertex-major, as motion_attributes reads it (one row per vertex); returned as a (T, V, 3) view
    out = np.empty((frames.shape[1], frames.shape[0], 3), np.float64).transpose(1, 0, 2)
    dist = np.empty((min(FRAME_BLOCK, len(frames)), frames.shape[1]), np.float64)
    for s in range(0, len(frames), FRAME_BLOCK):
        x = np.ascontiguousarray(frames[s:s + FRAME_BLOCK])
        n = len(x)
        weight = np.ones(x.shape[:2], np.bool_)
        for _ in range(rounds):
            h, c_fr, c_ref = np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3))
            _cross_covariance(x, ref, weight, h, c_fr, c_ref)
            u, _, vt = np.linalg.svd(h)
            fix = np.ones((n, 3))
            fix[:, 2] = np.sign(np.linalg.det(u @ vt))
            rot = (u * fix[:, None, :]) @ vt  # maps centred frame points onto the reference
            _residual(x, ref, rot, c_fr, c_ref, out[s:s + n], dist[:n])
            weight = dist[:n] <= np.median(dist[:n], axis=1, keepdims=True)
        progress("motion", (s + n) / len(frames))
    return out


@numba.njit(cache=True, nogil=True)
def _cross_covariance(x, ref, weight, h, c_fr, c_ref):
    """Per frame b of x (B, V, 3): the centroids of its weighted vertices and of theirs in ref, and the 3x3
    cross-covariance of the two centred point sets, into h (B, 3, 3), c_fr and c_ref (B, 3)."""
    for b in range(x.shape[0]):
        count = 0.0
        sf = np.zeros(3)
        sr = np.zeros(3)
        for v in range(x.shape[1]):
            if weight[b, v]:
                count += 1.0
                for i in range(3):
                    sf[i] += x[b, v, i]
                    sr[i] += ref[v, i]
        for i in range(3):
            c_fr[b, i] = sf[i] / count
            c_ref[b, i] = sr[i] / count
        acc = np.zeros((3, 3))
        for v in range(x.shape[1]):
            if weight[b, v]:
                for i in range(3):
                    a = x[b, v, i] - c_fr[b, i]
                    for j in range(3):
                        acc[i, j] += a * (ref[v, j] - c_ref[b, j])
        h[b] = acc


@numba.njit(cache=True, nogil=True)
def _residual(x, ref, rot, c_fr, c_ref, out, dist):
    """Per frame b: x centred, rotated by rot[b] onto ref's centroid, minus ref, into out (B, V, 3), and its
    length into dist (B, V)."""
    for v in range(x.shape[1]):  # vertex-major, as out is stored
        for b in range(x.shape[0]):
            a0 = x[b, v, 0] - c_fr[b, 0]
            a1 = x[b, v, 1] - c_fr[b, 1]
            a2 = x[b, v, 2] - c_fr[b, 2]
            sq = 0.0
            for j in range(3):
                d = a0 * rot[b, 0, j] + a1 * rot[b, 1, j] + a2 * rot[b, 2, j] + c_ref[b, j] - ref[v, j]
                out[b, v, j] = d
                sq += d * d
            dist[b, v] = np.sqrt(sq)


def motion_attributes(frames: np.ndarray, components: int = MOTION_COMPONENTS,
                      progress: Progress = no_progress) -> np.ndarray:
    """(V, components) float32: each vertex's deformation over the animation (head motion removed), projected
    on the main deformations, in units of the mesh's bounding-box diagonal."""
    if len(frames) > MOTION_FRAMES:  # the main deformations of a long capture show in evenly spaced frames
        frames = frames[np.unique(np.linspace(0, len(frames) - 1, MOTION_FRAMES).round().astype(np.int64))]
    t, v, _ = frames.shape
    # one row per vertex: its whole trajectory (the residual's half of the time; its eigenproblem the other)
    m = rigid_residual(frames, progress=span(progress, 0, 0.5)).transpose(1, 0, 2).reshape(v, 3 * t)
    gram = m.T @ m
    progress("motion", GRAM_DONE)
    _, vec = np.linalg.eigh(gram)
    del gram
    coords = m @ vec[:, ::-1][:, :components] / np.sqrt(t)  # RMS deformation along each main motion
    extent = float(np.linalg.norm(np.ptp(frames[0], axis=0))) or 1.0
    out = np.zeros((v, components), np.float32)
    out[:, : coords.shape[1]] = coords / extent
    progress("motion", 1.0)
    return out


def budget_shares(n_frames: int) -> tuple[float, float]:
    """Where on the budget's own progress the motion pass starts, and the deviation pass (the simplification
    between them takes next to nothing)."""
    facing, motion = BUDGET_MS["facing"] * n_frames, BUDGET_MS["motion"] * min(n_frames, MOTION_FRAMES)
    total = facing + motion + BUDGET_MS["deviation"] * n_frames
    return facing / total, (facing + motion) / total


def _part_simplify(fn, positions: np.ndarray, attrs: np.ndarray, lock: np.ndarray, faces: np.ndarray,
                   target: int, flags: int = 0, error: float = 1.0) -> np.ndarray:
    """One part's triangles simplified to about target triangles, or as far as meshoptimizer's relative error
    allows (vertices shared with other parts locked)."""
    idx = np.ascontiguousarray(faces.reshape(-1), np.uint32)
    dst = np.zeros_like(idx)
    weights = np.full(attrs.shape[1], MOTION_WEIGHT, np.float32)
    err = ctypes.c_float(0.0)
    n = fn(dst.ctypes.data_as(_P(ctypes.c_uint)), idx.ctypes.data_as(_P(ctypes.c_uint)), idx.size,
           positions.ctypes.data_as(_P(ctypes.c_float)), positions.shape[0], 12,
           attrs.ctypes.data_as(_P(ctypes.c_float)), attrs.shape[1] * 4, weights.ctypes.data_as(_P(ctypes.c_float)),
           attrs.shape[1], lock.ctypes.data_as(_P(ctypes.c_ubyte)), 3 * max(target, 1), error, flags, ctypes.byref(err))
    return dst[:n].reshape(-1, 3).astype(np.int32)


def _allocate(fn, positions: np.ndarray, attrs: np.ndarray, lock: np.ndarray, faces: np.ndarray,
              part_ids: np.ndarray, parts: np.ndarray, budget: int, flags: int = 0) -> list[np.ndarray]:
    """Each part simplified to its share of the budget; a part that cannot shrink that far keeps what it
    reached and the others share what is left."""
    share = np.array([(part_ids == p).sum() for p in parts], np.float64)
    fixed: dict[int, np.ndarray] = {}
    while len(fixed) < len(parts):
        free = [i for i in range(len(parts)) if i not in fixed]
        left = max(budget - sum(len(x) for x in fixed.values()), len(free))
        targets = {i: max(int(share[i] / share[free].sum() * left), 1) for i in free}
        result = {i: _part_simplify(fn, positions, attrs, lock, faces[part_ids == parts[i]], targets[i], flags)
                  for i in free}
        stuck = [i for i in free if len(result[i]) > targets[i]]
        if not stuck or sum(len(x) for x in result.values()) <= left:
            fixed.update(result)
            break
        fixed.update({i: result[i] for i in stuck})
    return [fixed[i] for i in range(len(parts))]


def front_facing_any(anim: FaceAnimation, options: ConversionOptions, progress: Progress = no_progress) -> np.ndarray:
    """Bool (F,): triangles front-facing and in view in at least one frame for the options' camera."""
    cam = fit_camera(anim, options.size, options.yaw, options.pitch, options.fov, options.ortho, options.frame_on)
    progress("facing", FIT_SHARE)
    seen = np.zeros(anim.n_faces, bool)
    for s in range(0, anim.n_frames, FRAME_BLOCK):
        xy, z, w = cam.project(anim.frames[s:s + FRAME_BLOCK])
        seen |= cull(xy, z, w, anim.faces, cam.width, cam.height).any(axis=0)
        progress("facing", FIT_SHARE + (1 - FIT_SHARE) * min(s + FRAME_BLOCK, anim.n_frames) / anim.n_frames)
    return seen


ATTACH_FRAMES = 8  # frames (evenly spaced, the first among them) that choose where an original vertex hangs on the
# simplified surface: the point that follows it best, not only the nearest at the first frame (lips that touch there)
ATTACH_CHUNK = 2048  # original vertices per block of that choice ((P, n, k, 3, 3) float64 corners at a time)
PER_VERTEX_EXTRAS = ("node_of_vertex", "joint_of_vertex", "framed_vertices")  # what framing reads, per vertex


def simplify(anim: FaceAnimation, max_triangles: int, report: Report,
             options: ConversionOptions | None = None, progress: Progress = no_progress) -> FaceAnimation:
    """The animation on a simplified mesh of at most max_triangles triangles (a subset of its vertices);
    progress through its passes over the frames (budget_shares).

    Under a bounded preset (the mobile one) max_triangles is a cap: each part is simplified as far as
    SIMPLIFY_BOUND allows (deviation in px, its silhouette at frame 0), and by count only when that needs more
    than the cap. Otherwise max_triangles is the count. Either way the report says what the budget did against
    the bound (budget_* figures) and warns, in words, when a visible part lost its area."""
    motion_from, deviation_from = budget_shares(anim.n_frames)
    if max_triangles < 4:
        raise InputError(f"max-triangles must be at least 4, got {max_triangles}.")
    faces, part_ids = anim.faces, anim.part_ids
    cam = None
    if options is not None:
        seen = front_facing_any(anim, options, span(progress, 0, motion_from))
        faces, part_ids = faces[seen], part_ids[seen]
        report.counts["budget_dropped_never_facing"] = int((~seen).sum())
        cam = fit_camera(anim, options.size, options.yaw, options.pitch, options.fov, options.ortho, options.frame_on)
    bounded = options is not None and options.preset in BOUNDED_PRESETS
    if not len(faces) or (len(faces) <= max_triangles and not bounded):
        out_faces, out_parts = faces, part_ids
    else:
        fn = _simplify_with_attributes()
        positions = np.ascontiguousarray(anim.frames[0], np.float32)
        attrs = np.ascontiguousarray(motion_attributes(anim.frames, progress=span(progress, motion_from,
                                                                                  deviation_from)))
        parts = np.unique(part_ids)
        owners = np.zeros(anim.n_vertices, np.int64)
        for p in parts:  # vertices used by two parts stay, so the parts still meet without cracks
            owners[np.unique(faces[part_ids == p])] += 1
        lock = np.ascontiguousarray(owners > 1, np.uint8)
        pieces = None
        if bounded:
            pieces = _bounded(anim, fn, positions, attrs, lock, faces, part_ids, parts, cam, SIMPLIFY_BOUND)
            if sum(len(x) for x in pieces) > max_triangles:
                report.warnings.append(
                    f"keeping the face within {SIMPLIFY_BOUND.max_px:g} px needs {sum(len(x) for x in pieces):,} "
                    f"triangles, more than the {max_triangles:,} allowed: simplified to {max_triangles:,} instead; "
                    f"raise --max-triangles to keep the face's shape")
                pieces = None  # by count: each part's share (_allocate) kept the ICT head's eyes and teeth better
                # than the bound's errors scaled up to fit (measured at 2,500 triangles)
        if pieces is None:
            pieces = _allocate(fn, positions, attrs, lock, faces, part_ids, parts, max_triangles)
        if sum(len(x) for x in pieces) > max_triangles:
            # Seams and many small pieces (lashes) cannot shrink that far: free the seams, drop small pieces.
            from meshoptimizer import SIMPLIFY_PRUNE  # noqa: PLC0415 - only newer meshoptimizer builds have it

            pieces = _allocate(fn, positions, attrs, np.zeros_like(lock), faces, part_ids, parts, max_triangles,
                               SIMPLIFY_PRUNE)
            report.warnings.append("the triangle budget needed part seams simplified and small pieces dropped")
        out_faces = np.concatenate(pieces)
        out_parts = np.concatenate([np.full(len(x), p, np.int32) for x, p in zip(pieces, parts)])
        if len(out_faces) > max_triangles:
            raise InputError(f"cannot simplify below {len(out_faces)} triangles; raise --max-triangles.")
    progress("simplify", deviation_from)
    simplified = _on_subset(anim, out_faces, out_parts)
    report.counts["budget_triangles"] = simplified.n_faces
    report.counts["budget_vertices"] = simplified.n_vertices
    if options is not None:
        worst, mean, per_part = budget_deviation_px(anim, simplified, faces, part_ids, options,
                                                    span(progress, deviation_from, 1.0))
        report.figures["budget_deviation_px"] = worst
        if mean is not None:  # no original vertex ever shown: no mean to give
            report.figures["budget_deviation_mean_px"] = mean
        for p, dev in per_part.items():  # mouth interior and teeth are mostly behind the lips: say so per part
            name = f"budget_deviation_px_{anim.parts[p].name}"
            report.figures[name] = max(report.figures.get(name, 0.0), dev)
        before = coverage_px(anim.frames[0], faces, part_ids, len(anim.parts), cam)
        after = coverage_px(anim.frames[0], out_faces, out_parts, len(anim.parts), cam)
        # leaving the preset out helps only when its own cap (not one the user gave) simplified this far
        preset_cap = bounded and max_triangles == PRESETS[options.preset].values.get("max_triangles")
        advice = f"raise --max-triangles{' or leave out --preset ' + options.preset if preset_cap else ''}"
        report_bound(report, anim, before, after, worst, mean, SIMPLIFY_BOUND, advice)
    return simplified


def report_bound(report: Report, anim: FaceAnimation, before: np.ndarray, after: np.ndarray, worst: float,
                 mean: float | None, bound: SimplifyBound, advice: str) -> None:
    """The budget's figures against the bound (budget_bound_*, budget_coverage_kept_*, budget_within_bound) and
    a warning in words, ending with advice, for each visible part that lost area and for a deviation past the
    bound; before and after are each part's pixels at frame 0."""
    report.figures["budget_bound_px"] = bound.max_px
    report.figures["budget_bound_mean_px"] = bound.mean_px
    lost = []
    for p in np.flatnonzero(before > 0):
        kept = float(after[p] / before[p])
        report.figures[f"budget_coverage_kept_{anim.parts[p].label}"] = kept
        if before[p] - after[p] > bound.lost_px(before[p]):
            lost.append(p)
            report.warnings.append(f"{part_word(anim.parts[p])} lost {1 - kept:.0%} of its visible area at frame 0 "
                                   f"to the triangle budget; {advice}")
    past = worst > bound.max_px or (mean is not None and mean > bound.mean_px)
    if past:
        report.warnings.append(
            f"the triangle budget moves the face by {mean or 0:.2f} px on average and up to {worst:.1f} px, past "
            f"its bound of {bound.mean_px:g} px on average and {bound.max_px:g} px at most; {advice}")
    report.figures["budget_within_bound"] = not (past or lost)


def part_word(part) -> str:
    """A part as a user reads it: its source name (node or mesh), once."""
    halves = part.label.split("/")
    return halves[0] if len(set(halves)) == 1 else part.label


def _on_subset(anim: FaceAnimation, faces: np.ndarray, part_ids: np.ndarray) -> FaceAnimation:
    """The animation on the triangles faces (indexing anim's vertices), with only the vertices they use."""
    used, inverse = np.unique(faces, return_inverse=True)
    return anim.with_frames(
        anim.frames[:, used], faces=inverse.reshape(-1, 3).astype(np.int32), part_ids=part_ids,
        vertex_colors=None if anim.vertex_colors is None else anim.vertex_colors[used],
        uvs=None if anim.uvs is None else anim.uvs[used],
        extras={**anim.extras, "simplified_from": [anim.n_vertices, anim.n_faces],
                **{k: anim.extras[k][used] for k in PER_VERTEX_EXTRAS if k in anim.extras}},
    )


def _bounded(anim: FaceAnimation, fn, positions: np.ndarray, attrs: np.ndarray, lock: np.ndarray,
             faces: np.ndarray, part_ids: np.ndarray, parts: np.ndarray, cam: Camera,
             bound: SimplifyBound) -> list[np.ndarray]:
    """Each part simplified as far as the bound allows: the largest meshoptimizer error (searched in log steps,
    every part at once) at which its vertices stay within bound px (mean and max, on PROBE_FRAMES frames) and it
    keeps its pixels at frame 0 among the other parts whole (bound.lost_px); then the parts that break the bound
    together are refined (FIX_ROUNDS), and a part no error keeps within it stays whole."""
    sample = anim.with_frames(anim.frames[probe_frames(anim.frames)])
    shown = part_image(anim.frames[0], faces, part_ids, cam)
    before = np.bincount(shown[shown >= 0], minlength=len(anim.parts))
    whole = [faces[part_ids == p] for p in parts]
    index = np.full(len(anim.parts) + 1, -1)
    index[parts] = np.arange(len(parts))  # part id -> its place in parts (-1: background)

    def within(pieces: list[np.ndarray], px: float, coverage: float,
               alone: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bool per part: its vertices within px times the bound, and its pixels within coverage times its loss
        (alone: each part simplified among the others whole, so that a part is not failed for what another's
        simplification covers); the pixels those that lost too many lost to another part, and what each pixel
        shows now."""
        out_faces = np.concatenate(pieces)
        out_parts = np.concatenate([np.full(len(x), p, np.int32) for x, p in zip(pieces, parts)])
        worst, total, count = _deviation_sums(sample, _on_subset(sample, out_faces, out_parts), faces, part_ids, cam)
        now = part_image(anim.frames[0], out_faces, out_parts, cam)
        after = np.bincount(now[now >= 0], minlength=len(anim.parts))
        for i in np.flatnonzero(before[parts] > 0) if alone else ():
            others = part_ids != parts[i]
            image = part_image(anim.frames[0], np.concatenate([faces[others], pieces[i]]),
                               np.concatenate([part_ids[others], np.full(len(pieces[i]), parts[i], np.int32)]), cam)
            after[parts[i]] = np.count_nonzero(image == parts[i])
        ok = np.ones(len(parts), bool)
        lost = np.zeros(shown.shape, bool)
        for i, p in enumerate(parts):
            mean = total.get(p, 0.0) / count[p] if count.get(p) else 0.0
            # a part keeps triangles to hang its vertices on (all of them face the camera in some frame)
            ok[i] &= (len(pieces[i]) > 0 and worst.get(p, 0.0) <= px * bound.max_px and mean <= px * bound.mean_px)
            if before[p] - after[p] > coverage * bound.lost_px(before[p]):
                ok[i] = False
                lost |= (shown == p) & (now != p) & (now >= 0)
        return ok, lost, now

    best, chosen = list(whole), np.zeros(len(parts))  # the error each part was simplified with, 0: whole
    lo, hi = np.full(len(parts), np.log(SEARCH_ERRORS[0])), np.full(len(parts), np.log(SEARCH_ERRORS[1]))
    for _ in range(SEARCH_STEPS):
        error = np.exp((lo + hi) / 2)
        pieces = [_part_simplify(fn, positions, attrs, lock, w, 1, 0, float(e)) for w, e in zip(whole, error)]
        ok = within(pieces, SEARCH_MARGIN, COVERAGE_MARGIN, alone=True)[0]
        for i in np.flatnonzero(ok):
            best[i], chosen[i] = pieces[i], error[i]
        lo, hi = np.where(ok, np.log(error), lo), np.where(ok, hi, np.log(error))
    # The parts that break the bound together: one that lost pixels to another (an eyelid drawn over the eye) keeps
    # that one's vertices around them; one that still breaks it is simplified less.
    lock = lock.copy()
    xy = np.nan_to_num(cam.project(anim.frames[0])[0], nan=-1.0, posinf=-1.0, neginf=-1.0)
    pixel = np.floor(np.clip(xy, -1, 1 << 20)).astype(np.int64)  # (V, 2) column, row at frame 0
    inside = (pixel >= 0).all(axis=1) & (pixel[:, 0] < cam.width) & (pixel[:, 1] < cam.height)
    for _ in range(FIX_ROUNDS):
        ok, lost, now = within(best, 1.0, 1.0)
        near = _dilate(lost, FIX_RADIUS)
        redo = {int(i) for i in np.flatnonzero(~ok & (chosen > 0))}
        locked = False
        for i in {int(index[q]) for q in np.unique(now[lost])} - redo:  # the parts drawn over lost pixels
            if not chosen[i]:
                continue  # whole already
            verts = np.unique(whole[i])
            verts = verts[inside[verts] & ~lock[verts].astype(bool)]
            verts = verts[near[pixel[verts, 1], pixel[verts, 0]]]
            if len(verts):
                lock[verts], locked = 1, True
                best[i] = _part_simplify(fn, positions, attrs, lock, whole[i], 1, 0, chosen[i])
            else:
                redo.add(i)
        if not redo and not locked:
            break  # within the bound, or nothing left to refine
        for i in redo:
            chosen[i] = chosen[i] / FIX_STEP if chosen[i] / FIX_STEP >= SEARCH_ERRORS[0] else 0.0
            best[i] = _part_simplify(fn, positions, attrs, lock, whole[i], 1, 0, chosen[i]) if chosen[i] else whole[i]
    return best


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """The bool image mask grown by radius pixels (a square)."""
    out = mask.copy()
    h, w = mask.shape
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] |= \
                mask[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return out


def probe_frames(frames: np.ndarray, n: int = PROBE_FRAMES) -> np.ndarray:
    """Sorted indices of at most n frames: the first, half evenly spaced, half those farthest from the first (the
    strongest expressions, where a simplification deviates most)."""
    spaced = np.linspace(0, len(frames) - 1, n // 2).round().astype(np.int64)
    far = np.empty(len(frames))
    for s in range(0, len(frames), FRAME_BLOCK):
        far[s:s + FRAME_BLOCK] = np.abs(frames[s:s + FRAME_BLOCK] - frames[0]).mean(axis=(1, 2))
    return np.unique(np.concatenate([[0], spaced, np.argsort(-far, kind="stable")[: n - n // 2]]))


def coverage_px(frame: np.ndarray, faces: np.ndarray, part_ids: np.ndarray, n_parts: int, cam: Camera) -> np.ndarray:
    """(n_parts,) int: the pixels each part shows in the frame (V, 3) as the id pass draws it (front faces in view,
    nearest wins), for the camera."""
    image = part_image(frame, faces, part_ids, cam)
    return np.bincount(image[image >= 0], minlength=n_parts)


def part_image(frame: np.ndarray, faces: np.ndarray, part_ids: np.ndarray, cam: Camera) -> np.ndarray:
    """(H, W) int: the part each pixel shows in the frame (V, 3), -1 for none (raster.draw_ids' triangle ids)."""
    v, h, w = len(frame), cam.height, cam.width
    fixed, xy, z = np.empty((v, 2), np.int64), np.empty((v, 2)), np.empty(v)
    m = np.ascontiguousarray(cam.projection @ cam.view, np.float64)
    raster.window_positions(np.ascontiguousarray(frame, np.float32), m, w, h, fixed, xy, z)
    pxy, pz, pw = cam.project(frame[None])
    drawn = np.ascontiguousarray(cull(pxy, pz, pw, faces, w, h)[0], np.bool_)
    ids, depth = np.empty((h, w), np.uint32), np.empty((h, w))
    raster.draw_ids(fixed, xy, z, np.ascontiguousarray(faces, np.int64), drawn, ids, depth, raster.ALL_TILES,
                    raster.WHOLE)
    return np.where(ids > 0, np.append(part_ids, -1)[ids.astype(np.int64) - 1], -1)


def budget_deviation_px(original: FaceAnimation, simplified: FaceAnimation, faces: np.ndarray,
                        part_ids: np.ndarray, options: ConversionOptions,
                        progress: Progress = no_progress) -> tuple[float, float | None, dict[int, float]]:
    """Max, mean (None when no vertex is ever shown) and per-part max distance in output px, over all frames,
    between each original vertex (of triangles that face the camera at that frame) and the point of the
    simplified surface it maps to (for the camera the output frames the simplified face with)."""
    cam = fit_camera(simplified, options.size, options.yaw, options.pitch, options.fov, options.ortho,
                     options.frame_on)
    per_part, total, count = _deviation_sums(original, simplified, faces, part_ids, cam, progress)
    n = sum(count.values())
    return max(per_part.values(), default=0.0), (sum(total.values()) / n if n else None), per_part


def _deviation_sums(original: FaceAnimation, simplified: FaceAnimation, faces: np.ndarray, part_ids: np.ndarray,
                    cam: Camera, progress: Progress = no_progress) -> tuple[dict, dict, dict]:
    """Per part with triangles left: the max, sum and count (vertex-frames shown) of the px distance between each
    original vertex and the point of the simplified surface it hangs on, over every frame.

    Each original vertex hangs on a point of the simplified mesh of its own part (barycentric coordinates), the
    one among its nearest at the first frame that follows it best over ATTACH_FRAMES frames (_follows_best)."""
    from scipy.sparse import csr_matrix  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast
    from scipy.spatial import cKDTree  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast
    from trimesh.triangles import closest_point, points_to_barycentric  # noqa: PLC0415 - heavy; loaded on first use to keep start-up fast

    sf, sp = simplified.faces, simplified.part_ids
    rest = simplified.frames[0].astype(np.float64)
    probe = np.unique(np.linspace(0, original.n_frames - 1, ATTACH_FRAMES).round().astype(np.int64))
    attached = []  # per part: its triangles, their vertices, and where each vertex hangs on the simplified mesh
    for p in np.unique(part_ids):
        tri_ids = np.flatnonzero(sp == p)
        if not len(tri_ids):
            continue
        of = faces[part_ids == p]
        verts, local = np.unique(of, return_inverse=True)
        pts = original.frames[0][verts].astype(np.float64)
        tris = rest[sf[tri_ids]]
        k = min(12, len(tri_ids))
        _, cand = cKDTree(tris.mean(axis=1)).query(pts, k=k)
        cand = cand.reshape(len(pts), k)
        flat_pts = np.repeat(pts, k, axis=0)
        cp = closest_point(tris[cand.reshape(-1)], flat_pts)
        cand_bary = barycentric(tris[cand.reshape(-1)], cp, points_to_barycentric).reshape(len(pts), k, 3)
        choice = _follows_best(original.frames[probe][:, verts], simplified.frames[probe],
                               sf[tri_ids[cand]], cand_bary)
        best = cand[np.arange(len(pts)), choice]
        bary = cand_bary[np.arange(len(pts)), choice]
        lf = local.reshape(-1, 3)
        incidence = csr_matrix((np.ones(lf.size, np.float32), (np.repeat(np.arange(len(lf)), 3), lf.ravel())),
                               shape=(len(lf), len(verts)))
        attached.append((int(p), part_ids == p, incidence, verts, sf[tri_ids[best]], bary))
    per_part = {p: 0.0 for p, *_ in attached}
    total, count = dict.fromkeys(per_part, 0.0), dict.fromkeys(per_part, 0)
    for s in range(0, original.n_frames, FRAME_BLOCK):  # float64 projections per block of frames, not per clip
        xy0, z0, w0 = cam.project(original.frames[s:s + FRAME_BLOCK])
        visible = cull(xy0, z0, w0, faces, cam.width, cam.height)  # (B, F) original triangles shown
        xy1, _, _ = cam.project(simplified.frames[s:s + FRAME_BLOCK])
        for p, in_part, incidence, verts, corner, bary in attached:
            # A vertex counts at a frame when one of its triangles is shown: (B, F) shown triangles times the
            # (F, n) triangle-vertex incidence.
            shown = (visible[:, in_part].astype(np.float32) @ incidence) > 0
            dev = np.empty(shown.shape)
            _deviation(xy0, xy1, verts, corner, bary, shown, dev)
            if dev.size:
                per_part[p] = max(per_part[p], float(dev.max()))
            total[p] += float(dev.sum())
            count[p] += int(shown.sum())
        progress("deviation", min(s + FRAME_BLOCK, original.n_frames) / original.n_frames)
    return per_part, total, count


def _follows_best(points: np.ndarray, frames: np.ndarray, corners: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Index (n,) of the candidate whose surface point (bary (n, k, 3) on triangles corners (n, k, 3)) stays
    closest, at its farthest over the probe frames, to each point (points (P, n, 3), frames (P, V, 3))."""
    out = np.empty(points.shape[1], np.int64)
    for s in range(0, len(out), ATTACH_CHUNK):
        c, b = corners[s:s + ATTACH_CHUNK], bary[s:s + ATTACH_CHUNK]
        on = np.einsum("pnkcj,nkc->pnkj", frames[:, c].astype(np.float64), b)  # (P, n, k, 3)
        far = np.linalg.norm(on - points[:, s:s + ATTACH_CHUNK, None].astype(np.float64), axis=-1).max(axis=0)
        out[s:s + ATTACH_CHUNK] = np.argmin(far, axis=1)
    return out


def barycentric(tris: np.ndarray, pts: np.ndarray, solve) -> np.ndarray:
    """Barycentric coordinates (n, 3) of points pts (n, 3) on triangles tris (n, 3, 3) by solve (trimesh's
    points_to_barycentric); on a degenerate triangle (zero area: a segment or a point), where solve divides by
    zero, those of the point's projection on its longest edge."""
    with np.errstate(divide="ignore", invalid="ignore"):
        bary = np.asarray(solve(tris, pts), np.float64)
    bad = np.flatnonzero(~np.isfinite(bary).all(axis=1))
    if len(bad):
        t, p = tris[bad], pts[bad]
        edges = np.array([(0, 1), (1, 2), (2, 0)])
        span_ = t[:, edges[:, 1]] - t[:, edges[:, 0]]  # (n, 3 edges, 3)
        longest = np.argmax(np.einsum("nej,nej->ne", span_, span_), axis=1)
        i, j = edges[longest, 0], edges[longest, 1]
        d = span_[np.arange(len(bad)), longest]
        dd = np.einsum("nj,nj->n", d, d)
        u = np.einsum("nj,nj->n", p - t[np.arange(len(bad)), i], d) / np.where(dd > 0, dd, 1.0)
        u = np.clip(np.where(dd > 0, u, 0.0), 0.0, 1.0)
        fix = np.zeros((len(bad), 3))
        fix[np.arange(len(bad)), i] = 1 - u
        fix[np.arange(len(bad)), j] += u
        bary[bad] = fix
    return bary


@numba.njit(cache=True, nogil=True)
def _deviation(xy0, xy1, verts, corner, bary, shown, out):
    """Per frame b and original vertex k (index verts[k]) of a part: the px from where it is (xy0) to the point it
    hangs on, bary[k] of the simplified triangle corner[k] (xy1), where shown, else 0; into out (B, n). numpy's
    arithmetic in numpy's order (the three corners summed in turn)."""
    for b in range(out.shape[0]):
        for k in range(out.shape[1]):
            if not shown[b, k]:
                out[b, k] = 0.0
                continue
            i0, i1, i2 = corner[k, 0], corner[k, 1], corner[k, 2]
            fx = bary[k, 0] * xy1[b, i0, 0] + bary[k, 1] * xy1[b, i1, 0] + bary[k, 2] * xy1[b, i2, 0]
            fy = bary[k, 0] * xy1[b, i0, 1] + bary[k, 1] * xy1[b, i1, 1] + bary[k, 2] * xy1[b, i2, 1]
            dx = fx - xy0[b, verts[k], 0]
            dy = fy - xy0[b, verts[k], 1]
            out[b, k] = np.sqrt(dx * dx + dy * dy)
