"""Shared animated colours (converter.encode.palette): every path plays a colour within the tolerance of its own."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from converter.encode import palette


def played(pal: palette.Palette, t: int) -> np.ndarray:
    """Levels (T, P, 3) each path plays, read from the held steps frame by frame (a reference loop)."""
    k = pal.size
    out = np.zeros((t, max(k, 1), 3))
    for e in range(k):
        held = None
        for f in range(t):
            if pal.mask[f, e]:
                held = pal.values[f, e]
            assert held is not None, "frame 0 is always a step"
            out[f, e] = held
    return out[:, np.maximum(pal.entry, 0)]


@st.composite
def tracks(draw):
    t = draw(st.integers(1, 12))
    p = draw(st.integers(1, 30))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    base = rng.uniform(0, 1, (1, p, 3))
    drift = rng.normal(0, draw(st.sampled_from([0.0, 0.01, 0.1, 0.4])), (t, 1, 3)).cumsum(axis=0)
    rgb = np.clip(base + drift * rng.uniform(0.5, 1.5, (1, p, 1)), 0, 1).astype(np.float32)
    active = rng.uniform(size=(t, p)) < draw(st.sampled_from([0.3, 0.8, 1.0]))
    tol = draw(st.sampled_from([0.6, 1.0, 3.0, 8.0, 12.5, 40.0, 255.0]))
    return rgb, active, tol


@settings(max_examples=120, deadline=None)
@given(tracks())
def test_every_shown_frame_of_every_path_plays_within_the_tolerance(case):
    rgb, active, tol = case
    t, p = active.shape
    pal = palette.build(rgb, np.arange(p), active, tol)
    shown = active.any(axis=0)
    assert ((pal.entry >= 0) == shown).all()  # a path never shown has no entry, every other one has one
    assert pal.size <= shown.sum() and (pal.size == 0 or set(pal.entry[shown]) == set(range(pal.size)))
    err = np.abs(played(pal, t) - rgb.astype(np.float64) * 255).max(axis=2)
    assert (err[active] <= tol + 1e-6).all()
    # the writer's error figure is the same measure
    assert np.allclose(np.sort(palette.played_error(rgb, np.arange(p), active, pal)), np.sort(err[active]), atol=1e-3)


def test_alike_tracks_share_an_entry_and_unlike_ones_do_not():
    t = 20
    ramp = np.linspace(0.2, 0.8, t)[:, None]
    a = np.repeat(ramp, 3, axis=1)  # grey rising
    b = a[::-1]  # grey falling: the same colours, another track
    rgb = np.stack([a, a + 2 / 255, a - 2 / 255, b, b + 1 / 255], axis=1).astype(np.float32)
    pal = palette.build(rgb, np.arange(5), np.ones((t, 5), bool), 8.0)
    assert pal.size == 2
    assert len(set(pal.entry[:3])) == 1 and len(set(pal.entry[3:])) == 1 and pal.entry[0] != pal.entry[3]
    assert pal.animated().all()
    # held steps: fewer keys than frames, within 8 levels of a ramp of 153 levels
    assert 153 / 16 <= pal.mask[:t, 0].sum() < t


def test_columns_of_a_wider_sheet_and_hidden_frames():
    rng = np.random.default_rng(2)
    wide = rng.uniform(0, 1, (6, 40, 3)).astype(np.float32)
    cols = np.array([3, 9, 9, 17, 30])
    active = np.ones((6, 5), bool)
    active[:, 4] = False  # never shown
    active[2:, 0] = False  # hidden after frame 1: its later colours are free
    pal = palette.build(wide, cols, active, 3.0)
    assert pal.entry[4] == -1 and (pal.entry[:4] >= 0).all()
    assert pal.entry[1] == pal.entry[2]  # the same column twice
    err = np.abs(played(pal, 6)[:, :4] - wide[:, cols[:4]] * 255).max(axis=2)
    assert (err[active[:, :4]] <= 3.0).all()


@pytest.mark.parametrize("tol", [0.6, 1.0, 3.0, 8.0, 8.4, 255.0])
def test_spread_limit_is_the_widest_that_rounds_within_tolerance(tol):
    # every pair of levels lo..hi within the limit: their rounded middle is within tol of any shade that rounds to
    # a level between them (a level stands for shades up to 0.5 away)
    s = palette.spread_limit(tol)
    for lo in range(0, 3):
        hi = lo + s
        mid = np.rint((lo + hi) / 2)
        assert max(abs(mid - (lo - 0.5)), abs(hi + 0.5 - mid)) <= tol
    mid = np.rint((0 + s + 1) / 2)  # one more level and a shade falls outside
    assert max(abs(mid + 0.5), abs(s + 1.5 - mid)) > tol or s >= 254
