"""Paths merged under --max-animations (converter.encode.merge): fewer elements, same drawing, same bound."""

import re

import numpy as np
import pytest

from converter import formats
from converter.encode import flatplan, merge
from converter.encode.budget import ErrorBudget
from converter.encode.tracks import Tracks
from converter.errors import InputError
from converter.extract import extract, fit_camera
from converter.options import PRESETS, ConversionOptions, Report
from converter.verify import _triangles_of_d, evaluate, verify_animation
from converter.writers import svg_anim
from svgrender import chromium_frame, iou


@pytest.fixture(scope="module")
def sample(sample_path):
    anim = formats.load(sample_path).sliced(0, 40)
    return anim, extract(anim, fit_camera(anim, 160))


def _write(sheet, **kw):
    report = Report()
    return svg_anim.write(sheet, ConversionOptions(size=160, **kw), report), report


def _elements(data: bytes) -> int:
    return len(re.findall(rb"<path ", data))


@pytest.mark.parametrize("colours", [255.0, 3.0])
def test_merged_file_keeps_the_bound_and_every_triangle(sample, colours):
    anim, sheet = sample
    plain, plain_report = _write(sheet, color_tolerance=colours, exact=True)  # one path per triangle
    data, report = _write(sheet, color_tolerance=colours, max_animations=60)
    v = verify_animation(data, anim)
    assert v.ok, v.summary()
    assert v.max_px <= 0.25
    assert sorted(evaluate(data).triangles.tolist()) == sorted(evaluate(plain).triangles.tolist())
    assert report.counts["paths"] == _elements(data) < _elements(plain) == plain_report.counts["paths"]
    assert report.counts["merged_triangles"] > report.counts["merged_paths"] > 0
    assert report.figures["color_error_max_levels"] <= colours  # merged colours stay within the tolerance
    if colours == 255.0:  # the sample's overlaps and colours leave 60 out of reach: as few as they allow
        assert report.counts["paths"] * 4 < plain_report.counts["paths"]
        assert report.counts["merge_palette"] == min(merge.PALETTES)
        assert report.figures["playback_ms_4x"] < plain_report.figures["playback_ms_4x"]


def test_merged_sets_keyed_in_size_bands_match_one_padded_width():
    """Sets are keyed in bands of sizes, each padded to its largest (not every set to the largest of all): the
    same texts and key count as one band padded to the widest set."""
    rng = np.random.default_rng(5)
    t, p = 40, 23
    base = rng.uniform(20, 200, (1, p, 6))
    track = base + np.cumsum(rng.normal(0, 0.6, (t, p, 6)), axis=0)
    active = rng.random((t, p)) > 0.1
    active[0] = True
    sets = [(0, 2), (2, 3), (3, 14), (14, 17), (17, 19), (19, 23)]
    sets = [s for s in sets if s[1] - s[0] > 1]
    budget = ErrorBudget.split(0.25, 256)
    tracks = Tracks(track.reshape(t, 3 * p, 2), np.arange(3 * p).reshape(p, 3))  # each corner its own vertex
    radius, gain = np.full(p, budget.keys), np.ones(p)
    closed = rng.random(p) > 0.3  # open subpaths too: the next moveto is relative to their last point
    bands = flatplan.merged_keys(tracks, active, radius, sets)
    one = flatplan.merged_band(tracks, active, radius, sets)
    banded = svg_anim._merged_geometry(bands, sets, gain, budget, t, "1.6s", closed)
    single = svg_anim._merged_geometry([one], sets, gain, budget, t, "1.6s", closed)
    assert len(bands) >= 3 and sorted(np.concatenate([b.sets for b in bands]).tolist()) == list(range(len(sets)))
    assert banded == single and all(banded[0]) and banded[2] > len(sets) * 2
    # each set's frame-0 d holds its paths' rounded frame-0 corners, open or closed (read back by the verifier)
    for (a, b), first in zip(sets, banded[1]):
        assert first.count("m") == b - a and first.count("z") == int(closed[a:b].sum())
        got = np.array(_triangles_of_d(first)).reshape(b - a, 6) / budget.scale
        assert np.abs(got - track[0, a:b])[active[0, a:b]].max() <= 2 * budget.tolerance


def test_without_a_budget_the_file_is_unchanged(sample):
    _, sheet = sample
    a, _ = _write(sheet, color_tolerance=255.0)
    b, _ = _write(sheet, color_tolerance=255.0, max_animations=10 ** 6)  # a budget already met merges nothing
    assert re.sub(rb'"max_animations":[^,]*', b"", a) == re.sub(rb'"max_animations":[^,]*', b"", b)


def test_reorder_keeps_every_overlapping_pair_and_groups_keys():
    rng = np.random.default_rng(3)
    p = 300
    key = rng.integers(0, 6, p)
    a = rng.integers(0, p, 400)
    b = rng.integers(0, p, 400)
    pairs = np.unique(np.column_stack([np.minimum(a, b), np.maximum(a, b)]), axis=0)
    pairs = pairs[(pairs[:, 0] != pairs[:, 1]) & (key[pairs[:, 0]] != key[pairs[:, 1]])]
    order = merge.by_runs(key, pairs)
    assert sorted(order.tolist()) == list(range(p))
    pos = np.argsort(order)
    assert (pos[pairs[:, 0]] < pos[pairs[:, 1]]).all()
    runs = lambda k: 1 + int((k[1:] != k[:-1]).sum())  # noqa: E731
    assert runs(key[order]) < runs(key) / 4


def test_sets_never_cross_a_group_and_share_colour_and_winding():
    t, p = 5, 40
    rng = np.random.default_rng(0)
    base = rng.uniform(0, 100, (p, 1, 2)) + np.array([[0, 0], [4, 0], [0, 4]])  # counter-clockwise in y-down
    xy = np.broadcast_to(base, (t, p, 3, 2)).copy()
    xy[:, ::7] = xy[:, ::7][:, :, [0, 2, 1]]  # every 7th winds the other way
    rgb = np.zeros((t, p, 3))
    rgb[:, :, 0] = (np.arange(p) % 2)[None] * 0.5
    segment = np.repeat([0, 1], p // 2)
    m = merge.plan(segment, rgb, np.ones((t, p), bool), 255.0, xy, 4)
    sign = merge.winding(xy[:, m.order], np.ones((t, p), bool))
    for a, b in zip(m.starts[:-1].tolist(), m.starts[1:].tolist()):
        assert len(set(segment[m.order[a:b]].tolist())) == 1
        assert len({tuple(c) for c in m.levels[a:b].tolist()}) == 1
        assert len(set(sign[a:b].tolist())) == 1


def test_verifier_reads_subpaths_with_relative_movetos():
    tri = _triangles_of_d("m10 10 5 0 0 5zm3 4 1 0 0 1zM50 50L60 50L50 60Z")
    assert tri == [10, 10, 15, 10, 15, 15, 13, 14, 14, 14, 14, 15, 50, 50, 60, 50, 50, 60]
    with pytest.raises(InputError):
        _triangles_of_d("m10 10 5 0zm1 1 1 1 1 1z")


def test_verifier_refuses_a_merged_path_its_metadata_does_not_list(sample):
    _, sheet = sample
    data, _ = _write(sheet, color_tolerance=255.0, max_animations=60)
    broken = re.sub(rb'"triangle_order":\[[^\]]*\]', b'"triangle_order":[]', data)
    with pytest.raises(InputError, match="triangle_order"):
        evaluate(broken)


@pytest.mark.browser
def test_chromium_draws_merged_paths_like_single_ones(browser, sample, artifacts):
    """Same silhouette at every sampled time and the colours within a palette's nearest colour."""
    anim, sheet = sample
    size = sheet.camera.width
    for colours in (3.0, 255.0):
        plain, _ = _write(sheet, color_tolerance=colours)
        data, report = _write(sheet, color_tolerance=colours, max_animations=60)
        assert report.counts["merged_paths"] > 0
        # Exact colours merge only paths of one shade; static ones take a palette's nearest colour. Reordered
        # neighbours swap which of their seam strokes (0.3 px either side of an edge) lies on top: 1.05 measured.
        mean_levels = 1.2 if colours == 3.0 else 6.0
        for k in (0, 13, 27, 39):
            a = chromium_frame(browser, plain, k / anim.fps, size, size)
            b = chromium_frame(browser, data, k / anim.fps, size, size)
            ma, mb = a[..., 3] > 127, b[..., 3] > 127
            assert iou(ma, mb) >= 0.99, f"frame {k}"
            diff = np.abs(a[..., :3].astype(int) - b[..., :3].astype(int))[ma & mb]
            assert diff.mean() <= mean_levels, f"frame {k}: mean colour difference {diff.mean():.2f}"
            if k == 27 and colours == 255.0:
                from PIL import Image

                Image.fromarray(np.concatenate([a, b], axis=1)).save(artifacts / "merged_paths.png")


@pytest.mark.browser
def test_mobile_preset_frame_structure_in_chromium(browser, sample_path):
    """What makes the mobile preset cheap to play, as Chromium's DOM holds it: at most its budget of animated
    paths, only d animations (no colour or class restyles), and the frames move."""
    from converter.convert import convert

    result = convert(sample_path, ConversionOptions(preset="mobile"))
    budget = PRESETS["mobile"].values["max_animations"]
    page = browser.new_page(viewport={"width": 256, "height": 256})
    try:
        page.set_content("<!doctype html><html><body style='margin:0'>" + result.data.decode() + "</body></html>")
        counts = page.evaluate("""() => ({
            paths: document.querySelectorAll('svg path').length,
            animated: new Set([...document.querySelectorAll('svg animate')].map(a => a.parentElement)).size,
            kinds: [...new Set([...document.querySelectorAll('svg animate')].map(
                a => a.getAttribute('attributeName')))],
            triangles: [...document.querySelectorAll('svg path')].reduce(
                (n, p) => n + (p.getAttribute('d').match(/m/gi) || []).length, 0)})""")
    finally:
        page.close()
    assert counts["paths"] == result.report.counts["paths"] <= budget
    assert 0 < counts["animated"] <= budget
    assert counts["kinds"] == ["d"]
    assert counts["triangles"] == result.report.counts["triangles_kept"]
    size = 256
    frames = [chromium_frame(browser, result.data, t, size, size) for t in (0.0, 1.0, 2.0)]
    assert all(np.abs(a.astype(int) - b.astype(int)).mean() > 0.3 for a, b in zip(frames, frames[1:]))
