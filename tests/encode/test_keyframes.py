"""Error-bounded keyframe reduction: the bound holds where active, hidden frames cost nothing, static is one key."""

import numpy as np
import pytest

from converter.encode import freeknots
from converter.encode import keys as kf


def interp_error(keys, x, active):
    y = kf.interpolate(keys)
    return (np.abs(y - x) * active[..., None]).max()


@pytest.mark.parametrize("eps", [0.05, 0.3, 2.0])
@pytest.mark.parametrize("reducer", [kf.reduce, freeknots.reduce_free], ids=["sampled", "free"])
def test_bound_holds_on_random_walks(eps, reducer):
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0, 0.4, (120, 50, 6)), axis=0)
    active = rng.random((120, 50)) > 0.2
    keys = reducer(x, active, eps)
    assert interp_error(keys, x, active) <= eps + freeknots.SLACK * (eps + np.abs(x).max() + 1)
    assert keys.mask[0].all() and keys.mask[-1].all()  # keyTimes start at 0 and end at 1


def test_smooth_motion_needs_few_keys_and_more_with_tighter_bound():
    t = np.arange(200)[:, None, None]
    x = 30 * np.sin(t / 25.0 + np.arange(4)[None, :, None]) * np.ones((1, 1, 2))
    active = np.ones((200, 4), bool)
    loose = kf.reduce(x, active, 0.5).mask.sum()
    tight = kf.reduce(x, active, 0.05).mask.sum()
    assert loose < 0.25 * 200 * 4 and tight > loose


def test_hidden_frames_are_free_and_static_tracks_keep_two_equal_keys():
    x = np.zeros((50, 2, 2))
    x[:, 1, 0] = np.where(np.arange(50) < 25, 0.0, 100.0) + np.arange(50) * 0  # jumps while hidden
    active = np.ones((50, 2), bool)
    active[20:30, 1] = False
    keys = kf.reduce(x, active, 0.1)
    assert keys.mask[:, 0].sum() == 2 and np.all(keys.values[[0, -1], 0] == 0)  # static
    assert keys.mask[:, 1].sum() <= 4
    assert interp_error(keys, x, active) <= 0.1


def test_never_active_track_has_no_keys():
    keys = kf.reduce(np.ones((10, 1, 2)), np.zeros((10, 1), bool), 0.1)
    assert not keys.mask.any() and keys.first_active[0] == -1


def numpy_reduce(x, active, eps):
    """kf.reduce as it was written before it was compiled: one loop over frames, vectorised over tracks."""
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
    return kf.Keys(mask, values, first)


@pytest.mark.parametrize("seed", range(4))
def test_compiled_reduce_gives_the_keys_of_the_vectorised_one(seed):
    rng = np.random.default_rng(seed)
    t, n = int(rng.integers(2, 300)), int(rng.integers(1, 40))
    x = np.cumsum(rng.normal(0, rng.uniform(0.05, 3), (t, n, 6)), axis=0) * 10.0 ** rng.integers(-2, 3)
    x[:, : n // 4] = np.round(x[:, : n // 4])  # ties on the box's edges
    active = rng.random((t, n)) > rng.uniform(0, 0.9)
    active[:, 0] = False  # never shown
    active[0, -1] = False  # first shown later
    eps = rng.uniform(0.01, 2, n)
    got, want = kf.reduce(x, active, eps), numpy_reduce(x, active, eps)
    assert np.array_equal(got.mask, want.mask) and np.array_equal(got.first_active, want.first_active)
    assert np.array_equal(got.values, want.values)  # bit for bit: the same arithmetic in the same order


def numpy_uniform_check(x, active, n_keys, q, scale, radius, pairs):
    """uniform_fit's check as numpy computed it before it was compiled (the reference)."""
    from converter.arrays import lengths

    t, n, d = x.shape
    a = kf._hat(t, n_keys)
    flat = x.reshape(t, n * d)
    dev = a @ (q.reshape(n_keys, n * d) / scale) - flat
    dev = dev.reshape(t, n, d // 2, 2) if pairs else dev.reshape(t, n, d, 1)
    err = (lengths(dev) if pairs else np.abs(dev[..., 0])).max(axis=-1)
    return ~(np.where(active, err, 0.0) > radius).any(axis=0)


@pytest.mark.parametrize("pairs", [True, False])
@pytest.mark.parametrize("n_keys", [2, 7, 40])
def test_compiled_uniform_check_is_the_numpy_one(pairs, n_keys):
    # Random walks with hidden frames, per-track radii around the fits' errors (both outcomes, often).
    rng = np.random.default_rng(n_keys)
    t, n, d = 97, 300, 6
    x = np.cumsum(rng.normal(0, 0.3, (t, n, d)), axis=0)
    active = rng.random((t, n)) > 0.15
    scale = 100.0
    outcomes = set()
    for radius in (0.2, 1.5, rng.uniform(0.05, 4.0, n)):
        q, ok = kf.uniform_fit(x, active, n_keys, scale, radius, pairs)
        want = numpy_uniform_check(x, active, n_keys, q, scale, radius, pairs)
        assert np.array_equal(ok, want)
        outcomes |= set(want.tolist())
    assert outcomes == {True, False}
