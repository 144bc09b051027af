"""Error-bounded keyframe reduction: per track, the few keys whose linear interpolation stays within a bound.

A track is a vector of D numbers per frame (a triangle's 3 vertices: D = 6). Constraints apply only at the
frames where the track is *active* (its triangle is visible); elsewhere interpolation may wander freely, which
is the chapter's "drop coordinates while hidden" generalised.

The reduction is a greedy "feasible velocity cone" (a box here: one interval per coordinate): from the current
start key (time s, value p), a straight segment to a later key at frame e passes within ``eps`` of every active
frame k in between iff its velocity lies in the intersection of the intervals
``[(x_k - p - eps) / (k - s), (x_k - p + eps) / (k - s)]``. Each frame updates the box in O(D); when the next
active frame cannot be reached inside the box, the previous active frame becomes a key. Every track advances
together, so the whole reduction is one loop over frames vectorised over tracks.

The first key sits at time 0 holding the value of the first active frame; the last key sits at time T (SMIL's
keyTimes end at 1) and its value is free: any velocity in the final box extrapolates to a valid end, and zero
velocity is preferred, so a track that never moves beyond ``eps`` comes out as two equal keys (static).

Keys on sampled values are what the transform stacks and the exact (``--raw``) encoding need. Paths' vertices
and colours use ``converter.encode.freeknots`` instead, whose key values are free within the bound (fewer keys)
and which falls back on ``reduce`` here for the few tracks its compiled pass rejects.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.linalg import solveh_banded


class Keys(NamedTuple):
    """Kept keyframes of N tracks over T frames: key mask over frames 0..T and the key values."""

    mask: np.ndarray  # bool (T + 1, N): frame k (k = T is the loop end) is a key of track n
    values: np.ndarray  # float (T + 1, N, D): value at each key (undefined where not a key); float32 from point_keys
    first_active: np.ndarray  # int (N,): first active frame, -1 when the track is never active


def reduce(x: np.ndarray, active: np.ndarray, eps: float | np.ndarray) -> Keys:
    """Greedy keys on sampled values for tracks x (T, N, D), within eps per coordinate where active."""
    x = np.asarray(x, np.float64)
    t, n, d = x.shape
    active = np.asarray(active, bool)
    eps = np.broadcast_to(np.asarray(eps, np.float64), (n,))[:, None]
    first = np.where(active.any(axis=0), np.argmax(active, axis=0), -1)
    live = first >= 0
    mask = np.zeros((t + 1, n), bool)
    values = np.zeros((t + 1, n, d), np.float64)
    # Start: a key at time 0 holding the first active value (frames before it are hidden).
    start_t = np.zeros(n, np.int64)
    start_v = x[np.maximum(first, 0), np.arange(n)]
    mask[0] = live
    values[0] = start_v
    lo = np.full((n, d), -np.inf)
    hi = np.full((n, d), np.inf)
    last_t = np.where(first == 0, 0, -1)  # latest active frame after the start (always a feasible end)
    inv_dt = np.empty((n, 1))
    for k in range(1, t):
        act = active[k]
        if not act.any():
            continue
        all_act = bool(act.all())
        xk = x[k]
        np.divide(1.0, (k - start_t)[:, None], out=inv_dt)
        rel = xk - start_v
        v = rel * inv_dt
        reachable = ((v >= lo) & (v <= hi)).all(axis=1)
        # Not reachable inside the box: the previous active frame becomes a key and the new start.
        cut = act & ~reachable & (last_t > start_t)
        if cut.any():
            idx = np.flatnonzero(cut)
            kt = last_t[idx]
            end = x[kt, idx]
            mask[kt, idx] = True
            values[kt, idx] = end
            start_t[idx] = kt
            start_v[idx] = end
            lo[idx] = -np.inf
            hi[idx] = np.inf
            inv_dt[idx] = 1.0 / (k - kt)[:, None]
            rel[idx] = xk[idx] - end
        new_lo = (rel - eps) * inv_dt
        new_hi = (rel + eps) * inv_dt
        if all_act:
            np.maximum(lo, new_lo, out=lo)
            np.minimum(hi, new_hi, out=hi)
            last_t[:] = k
        else:
            sel = act[:, None]
            np.copyto(lo, np.maximum(lo, new_lo), where=sel)
            np.copyto(hi, np.minimum(hi, new_hi), where=sel)
            last_t[act] = k
    # Loop end: free value on the last segment. Zero velocity when the box allows it, else the velocity to the
    # last active frame, which is always inside the box (and consistent across coordinates).
    zero_ok = ((lo <= 0) & (hi >= 0)).all(axis=1)
    has = last_t > start_t
    span = np.where(has, last_t - start_t, 1)[:, None]
    v_last = (x[np.maximum(last_t, 0), np.arange(n)] - start_v) / span
    vel = np.where((zero_ok | ~has)[:, None], 0.0, v_last)
    mask[t] = live
    values[t] = start_v + (t - start_t)[:, None] * vel
    return Keys(mask, values, first)


def interpolate(keys: Keys, frames: np.ndarray | None = None) -> np.ndarray:
    """Linear interpolation of the keys at integer frames (default 0..T-1): (len(frames), N, D)."""
    mask, values = keys.mask, keys.values
    t1, n, d = values.shape
    frames = np.arange(t1 - 1) if frames is None else np.asarray(frames)
    out = np.zeros((len(frames), n, d))
    for j in range(n):  # reference implementation for tests; the verifier evaluates the SVG itself
        kt = np.flatnonzero(mask[:, j])
        if len(kt) == 0:
            continue
        for c in range(d):
            out[:, j, c] = np.interp(frames, kt, values[kt, j, c])
    return out


def fewest(a: Keys, b: Keys) -> Keys:
    """Per track the keys of a or b, whichever has fewer (a on ties)."""
    win = b.mask.sum(axis=0) < a.mask.sum(axis=0)
    return Keys(np.where(win, b.mask, a.mask), np.where(win[:, None], b.values, a.values), a.first_active)


def _hat(n_frames: int, n_keys: int):
    """Sparse (T, n) matrix of linear interpolation from n evenly spaced keys over [0, T] to frames 0..T-1."""
    h = n_frames / (n_keys - 1)
    k = np.arange(n_frames)
    i = np.minimum(np.floor(k / h).astype(np.int64), n_keys - 2)
    f = k / h - i
    rows = np.concatenate([k, k])
    cols = np.concatenate([i, i + 1])
    return sparse.csr_matrix((np.concatenate([1 - f, f]), (rows, cols)), shape=(n_frames, n_keys))


def uniform_fit(x: np.ndarray, active: np.ndarray, n_keys: int, scale: float,
                radius: float | np.ndarray, pairs: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Evenly spaced keys (no keyTimes needed) for tracks x (T, N, D), least-squares fitted and rounded to the
    1/scale grid. Returns integer key values (n_keys, N, D) and whether every track stays within radius of x at
    every active frame, rounding included: Euclidean per 2D point when pairs, else per coordinate."""
    t, n, d = x.shape
    a = _hat(t, n_keys)
    lam = 1e-6  # keys without frames (none between the last frame and the loop end) hold the sampled value
    tau = np.minimum(np.arange(n_keys) * t / (n_keys - 1), t - 1)
    lo = np.floor(tau).astype(np.int64)
    hi = np.minimum(lo + 1, t - 1)
    w = (tau - lo)[:, None]
    flat = x.reshape(t, n * d)
    prior = flat[lo] * (1 - w) + flat[hi] * w
    ata = (a.T @ a).tocsr()
    band = np.zeros((2, n_keys))
    band[1] = ata.diagonal() + lam
    band[0, 1:] = ata.diagonal(1)
    v = solveh_banded(band, a.T @ flat + lam * prior)
    q = np.rint(v * scale)
    dev = (a @ (q / scale) - flat).reshape(t, n, d // 2, 2) if pairs else (a @ (q / scale) - flat).reshape(t, n, d, 1)
    err = (np.linalg.norm(dev, axis=-1) if pairs else np.abs(dev[..., 0])).max(axis=-1)
    ok = ~(np.where(active, err, 0.0) > radius).any(axis=0)
    return q.reshape(n_keys, n, d).astype(np.int64), ok
