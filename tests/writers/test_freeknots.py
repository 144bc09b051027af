"""Free-knot keys: the bound holds where active, fewer keys than sampled keys, still tracks stay two equal keys."""

import numpy as np

from converter.encode import freeknots, parallel
from converter.encode import keys as kf


def max_error(keys, x, active):
    return (np.abs(kf.interpolate(keys) - x) * active[..., None]).max()


def within(err, eps, x):
    """The documented bound: eps plus rounding far below any writer's float margin."""
    return err <= eps + freeknots.SLACK * (eps + np.abs(x).max() + 1)


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
    early = freeknots.point_keys(x, active, 0.25, freeknots.SHAPES_DEG[1:], best=first)
    assert np.array_equal(early.mask, full.mask) and np.array_equal(early.values, full.values)
    assert np.array_equal(freeknots.point_keys(x, active, 0.25).mask, full.mask)


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

    def reject_all(x, active, eps, limit, mask, values, bad, gave_up, first, stop):
        bad[first:stop] = True

    monkeypatch.setattr(freeknots, "_reduce", reject_all)
    keys = freeknots.reduce_free(x, active, 0.3)
    sampled = kf.reduce(x, active, 0.3)
    assert np.array_equal(keys.mask, sampled.mask) and np.array_equal(keys.values, sampled.values)


def test_same_keys_on_one_thread(monkeypatch):
    x, active = noisy_sines()
    many = freeknots.reduce_free(x, active, 0.2)
    monkeypatch.setattr(parallel, "THREADS", 1)
    one = freeknots.reduce_free(x, active, 0.2)
    assert np.array_equal(many.mask, one.mask) and np.array_equal(many.values, one.values)
