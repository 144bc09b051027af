"""Free-knot keys: the bound holds where active, fewer keys than sampled keys, still tracks stay two equal keys."""

import numpy as np
import pytest

from converter.encode import freeknots, parallel
from converter.encode import keys as kf


def max_error(keys, x, active):
    return (np.abs(kf.interpolate(keys) - x) * active[..., None]).max()


def within(err, eps, x):
    """The documented bound: eps plus rounding far below any writer's float margin, plus point_keys' float32
    storage of the key values (half an ulp a coordinate; budget.FLOAT_ERR_PER_PX counts it)."""
    size = eps + np.abs(x).max() + 1
    return err <= eps + freeknots.SLACK * size + 2.0 ** -24 * np.sqrt(2) * size


def noisy_sines(t=200, n=40, d=6, noise=0.15, seed=7):
    rng = np.random.default_rng(seed)
    k = np.arange(t)[:, None, None]
    x = 20 * np.sin(k / rng.uniform(8, 40, (1, n, d)) + rng.uniform(0, 6, (1, n, d)))
    return x + rng.normal(0, noise, x.shape), rng.random((t, n)) > 0.15


def test_fewer_keys_than_sampled_keys_on_noisy_motion():
    x, active = noisy_sines()
    free = freeknots.reduce_free(x, active, 0.3)
    sampled = kf.reduce(x, active, 0.3)
    assert within(max_error(free, x, active), 0.3, x)
    assert free.mask.sum() < 0.85 * sampled.mask.sum()


def test_point_keys_keep_the_euclidean_bound():
    x, active = noisy_sines(n=30)
    keys = freeknots.point_keys(x, active, 0.25)
    err = np.linalg.norm((kf.interpolate(keys) - x).reshape(*x.shape[:2], 3, 2), axis=-1).max(axis=-1)
    assert within(err[active].max(), 0.25, x)


def test_shapes_against_a_best_stop_early_with_the_same_keys():
    """Tracks of a later shape give up once they cannot beat the best so far: the same keys as every shape
    reduced in full and the fewest taken (ties to the earlier)."""
    x, active = noisy_sines(n=60, noise=0.3)
    first = freeknots.point_keys(x, active, 0.25, freeknots.SHAPES_DEG[:1])
    full = first
    for a in freeknots.SHAPES_DEG[1:]:
        full = kf.fewest(full, freeknots.point_keys(x, active, 0.25, (a,)))
    assert (full.mask.sum(axis=0) < first.mask.sum(axis=0)).any()  # the later shapes do win somewhere
    early = freeknots.point_keys(x, active, 0.25, freeknots.SHAPES_DEG[1:], best=first, exhaustive=True)
    assert np.array_equal(early.mask, full.mask) and np.array_equal(early.values, full.values)
    assert np.array_equal(freeknots.point_keys(x, active, 0.25, exhaustive=True).mask, full.mask)
    guided = freeknots.point_keys(x, active, 0.25)  # each later shape only where the jitter leans its way
    squares = freeknots.point_keys(x, active, 0.25, freeknots.SHAPES_DEG[:1])  # first holds `early` now
    assert (guided.mask.sum(axis=0) <= squares.mask.sum(axis=0)).all()
    assert (guided.mask.sum(axis=0) >= full.mask.sum(axis=0)).all()


def test_the_shape_tried_is_the_one_the_jitter_leans_towards():
    """Jitter along y only: the tall rectangle (60 degrees) needs fewest keys and is the one tried; along x only,
    the wide one (30 degrees). A track that never bends tries none."""
    rng = np.random.default_rng(3)
    t, n = 150, 13
    base = np.cumsum(rng.normal(0, 0.05, (t, n, 6)), axis=0)  # slow drift on both axes
    jitter = rng.normal(0, 0.4, (t, n, 6))
    x = base.copy()
    x[:, :4, 1::2] += jitter[:, :4, 1::2]  # tracks 0-3: y
    x[:, 4:8, 0::2] += jitter[:, 4:8, 0::2]  # tracks 4-7: x
    x[:, 8:12] += jitter[:, 8:12]  # tracks 8-11: both
    x[:, 12] = 5.0  # track 12: still, no bend
    active = np.ones((t, n), bool)
    lean = freeknots.lean_deg(x, active)
    assert (lean[:4] > 60).all() and (lean[4:8] < 30).all() and (np.abs(lean[8:12] - 45) < 7.5).all()
    assert np.isnan(lean[12])
    active[::7, 2] = False  # a block of tracks read from the whole array (one kernel signature) is the same
    part = freeknots.lean_deg(x, active[:, 2:9], 2)
    np.testing.assert_array_equal(part, freeknots.lean_deg(np.ascontiguousarray(x[:, 2:9]), active[:, 2:9]))
    assert part[0] != lean[2]  # the hidden frames count
    with pytest.raises(ValueError):
        freeknots.lean_deg(x, active[:, 2:9], 7)  # tracks 7..13 are not all there
    active[::7, 2] = True
    calls = []
    real = freeknots._reduce_block
    try:
        freeknots._reduce_block = lambda x, act, *a, **k: calls.append(act.shape[1]) or real(x, act, *a, **k)
        guided = freeknots.point_keys(x, active, 0.5)
    finally:
        freeknots._reduce_block = real
    assert calls == [n, 6, 6]  # the square for all, then each rectangle on its side's 6 bending tracks
    full = freeknots.point_keys(x, active, 0.5, exhaustive=True)
    squares = freeknots.point_keys(x, active, 0.5, freeknots.SHAPES_DEG[:1])
    g, f, sq = (k.mask.sum(axis=0) for k in (guided, full, squares))
    assert (g[:8] == f[:8]).all() and (g[:8] < sq[:8]).all()  # the leaning tracks get the best shape
    assert (g <= sq).all() and g[12] == sq[12]
    err = np.linalg.norm((kf.interpolate(guided) - x).reshape(t, n, 3, 2), axis=-1).max()
    assert within(err, 0.5, x)


def test_still_hidden_and_never_active_tracks():
    x = np.zeros((50, 3, 2))
    x[:, 0] += np.random.default_rng(1).uniform(-0.05, 0.05, (50, 2))  # jitter inside the bound: still
    x[25:, 1, 0] = 100.0  # jumps while hidden
    active = np.ones((50, 3), bool)
    active[20:30, 1] = False
    active[:, 2] = False
    keys = freeknots.reduce_free(x, active, 0.1)
    assert keys.mask[:, 0].sum() == 2 and np.array_equal(keys.values[0, 0], keys.values[-1, 0])
    assert keys.mask[:, 1].sum() <= 4 and within(max_error(keys, x, active), 0.1, x)
    assert not keys.mask[:, 2].any() and keys.first_active[2] == -1


def test_tracks_the_compiled_pass_rejects_get_sampled_keys(monkeypatch):
    x, active = noisy_sines(n=8)

    def reject_all(x, cols, scale, active, eps, limit, mask, values, bad, gave_up, first, stop):
        bad[first:stop] = True

    monkeypatch.setattr(freeknots, "_reduce", reject_all)
    keys = freeknots.reduce_free(x, active, 0.3)
    sampled = kf.reduce(x, active, 0.3)
    assert np.array_equal(keys.mask, sampled.mask) and np.array_equal(keys.values, sampled.values)


def test_rejected_point_tracks_get_sampled_keys_scaled_back(monkeypatch):
    x, active = noisy_sines(n=8)

    def reject_all(x, cols, scale, active, eps, limit, mask, values, bad, gave_up, first, stop):
        bad[first:stop] = True

    monkeypatch.setattr(freeknots, "_reduce", reject_all)
    keys = freeknots.point_keys(x, active, 0.3, freeknots.SHAPES_DEG[:1])
    scale = freeknots._scale(freeknots.SHAPES_DEG[0], 3)
    sampled = kf.reduce(x * scale, active, 0.3)
    assert keys.values.dtype == np.float32 and np.array_equal(keys.mask, sampled.mask)
    assert np.array_equal(keys.values, (sampled.values / scale).astype(np.float32))


def test_same_keys_on_one_thread(monkeypatch):
    x, active = noisy_sines()
    many = freeknots.reduce_free(x, active, 0.2)
    monkeypatch.setattr(parallel, "THREADS", 1)
    one = freeknots.reduce_free(x, active, 0.2)
    assert np.array_equal(many.mask, one.mask) and np.array_equal(many.values, one.values)
