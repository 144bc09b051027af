"""Visibility folded into the geometry keys (converter.encode.collapse) and what it costs players."""

import numpy as np
import pytest

from converter import formats, playcost
from converter.encode import collapse, freeknots
from converter.encode.keys import Keys, interpolate
from converter.errors import InputError
from converter.extract import extract, fit_camera
from converter.options import PRESETS, ConversionOptions, Report
from converter.writers import svg_anim


def _play(tl: collapse.Timeline, p: int, t: int) -> np.ndarray:
    """The timeline's linear interpolation at frames 0..T-1: (T, P, D)."""
    out = np.zeros((t, p, tl.values.shape[1]))
    for j in range(p):
        sel = tl.path == j
        for c in range(tl.values.shape[1]):
            out[:, j, c] = np.interp(np.arange(t) * 2.0, tl.half[sel], tl.values[sel, c])
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hidden_frames_collapse_and_visible_frames_play_as_before(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    t, p = 40, 30
    track = np.cumsum(rng.normal(0, 0.6, (t, p, 6)), axis=0) + rng.uniform(0, 50, (1, p, 6))
    active = rng.random((t, p)) > 0.3
    active[:, 0] = True  # one path always shown
    active[5:9, 1] = False
    active[:, 1] |= np.arange(t) >= 9
    keys = freeknots.point_keys(track, active, 0.3)
    tl = collapse.fold(keys, active)
    played, before = _play(tl, p, t), interpolate(keys)
    np.testing.assert_allclose(played[active], before[active], atol=1e-5)  # keys and edge values are float32
    tri = played.reshape(t, p, 3, 2)
    point = (tri == tri[:, :, :1]).all(axis=(2, 3))
    assert (point == ~active).all()
    assert (np.diff(tl.half)[tl.path[1:] == tl.path[:-1]] > 0).all()  # strictly increasing per path
    # Collapses sit on half frames (or the loop's ends); an always-shown path is unchanged.
    assert ((tl.half[tl.collapsed] % 2 == 1) | np.isin(tl.half[tl.collapsed], [0, 2 * t])).all()
    assert tl.collapsed[tl.path == 0].sum() == 0 and (tl.path == 0).sum() == keys.mask[:, 0].sum()
    monkeypatch.setattr(collapse, "FOLD_CELLS", 3 * t)  # blocks of three paths: the same timeline
    blocks = collapse.fold(keys, active)
    assert all(np.array_equal(x, y) for x, y in zip(blocks, tl)) and len(blocks.path) == len(tl.path)


def test_keytimes_keep_edges_on_their_side():
    t = 10
    active = np.ones((t, 1), bool)
    active[4:6] = False
    mask = np.zeros((t + 1, 1), bool)
    mask[[0, 3, 8, 10]] = True
    values = np.zeros((t + 1, 1, 6))
    values[:, 0] = np.arange(t + 1)[:, None] * np.array([10, 0, 10, 5, 12, 0])
    tl = collapse.fold(Keys(mask, values, np.zeros(1, int)), active)
    text, _ = svg_anim.timeline_key_times(tl, np.rint(tl.values * 12).astype(np.int64), t, 1 / 12, 0.004)
    kt = np.array([float(x) for x in text]) * 2 * t  # in half frames
    assert (np.diff(kt) > 0).all()
    assert (kt[tl.snap == 1] >= tl.half[tl.snap == 1]).all() and (kt[tl.snap == -1] <= tl.half[tl.snap == -1]).all()
    assert (np.abs(kt[tl.collapsed] - tl.half[tl.collapsed]) < 0.5).all()


@pytest.fixture(scope="module")
def sample_sheet(sample_path):
    anim = formats.load(sample_path).sliced(0, 24)
    return extract(anim, fit_camera(anim, 128))


def test_exact_colours_by_option_shared_by_default_and_static_by_option(sample_sheet):
    fast, shared, exact = Report(), Report(), Report()
    a = svg_anim.write(sample_sheet, ConversionOptions(size=128, color_tolerance=255), fast)
    b = svg_anim.write(sample_sheet, ConversionOptions(size=128), shared)
    svg_anim.write(sample_sheet, ConversionOptions(size=128, exact=True), exact)
    assert b'attributeName="color"' not in a and b'attributeName="class"' not in a
    assert exact.counts["color_animations"] > 0 and exact.figures["color_error_max_levels"] <= 3
    assert 3 < shared.figures["color_error_max_levels"] <= 8  # the default tolerance, reported
    assert shared.counts["color_animations"] < exact.counts["color_animations"] and b'attributeName="color"' not in b
    assert fast.figures["color_error_max_levels"] > 8  # the cost of static colours, reported
    assert fast.figures["playback_ms_4x"] < exact.figures["playback_ms_4x"]
    assert shared.figures["playback_ms_4x"] < exact.figures["playback_ms_4x"]


def test_mobile_preset_fills_defaults_only():
    mobile = PRESETS["mobile"].values
    o = ConversionOptions(preset="mobile")
    assert all(getattr(o, k) == v for k, v in mobile.items())
    assert ConversionOptions(preset="mobile", size=300).size == 300
    assert ConversionOptions.from_mapping({"preset": "mobile"}).max_triangles == mobile["max_triangles"]
    # A value given explicitly stays even when it equals the default (the CLI, the API and the form say so).
    assert ConversionOptions.from_mapping({"preset": "mobile", "size": 512}).size == 512
    given = ConversionOptions.given(preset="mobile", tolerance=0.25, max_animations=None)
    assert (given.tolerance, given.max_animations, given.size) == (0.25, None, mobile["size"])
    with pytest.raises(InputError):
        ConversionOptions(preset="tiny")


def test_playback_classes_order_by_cost():
    light = playcost.predict_ms({"paths": 500, "animated_paths": 100})
    heavy = playcost.predict_ms({"paths": 1300, "animated_paths": 1300, "color_animations": 1000})
    assert playcost.playback_class(light) == playcost.CLASSES[0][1]
    assert playcost.playback_class(heavy) == playcost.HEAVY



def test_the_playback_description_says_what_plays_on_phones():
    """A file not light enough for phones says its predicted phone frame rate and what to use instead; a light one
    says only its class (the CLI summary's words)."""
    light = playcost.describe(20.0)
    slow = playcost.describe(250.0)
    assert light == playcost.CLASSES[0][1]
    assert slow.startswith(playcost.HEAVY) and "~4 fps" in slow and "--preset mobile" in slow
    summary = Report(counts={"frames": 3}, figures={"playback_ms_4x": 250.0}).summary()
    assert "~4 fps on a mid-range phone" in summary
