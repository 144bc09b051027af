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
