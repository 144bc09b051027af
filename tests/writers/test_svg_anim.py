"""The animated SVG writer: raw, the chapter's post-optimisations, and the error-bounded default encoding."""

import dataclasses
import gzip
import re

import numpy as np
import pytest
from lxml import etree

from conftest import cube_animation
from converter import extract
from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation
from converter.encode import colours, freeknots
from converter.encode.budget import viewbox_scale
from converter.encode.keys import Keys, interpolate
from converter.options import ConversionOptions, Report
from converter.verify import _triangles_of_d, verify_animation
from converter.writers import svg_anim
from converter.writers.svg_anim import _path_strings, offsets
from verify.synth import grid

SVG = "{http://www.w3.org/2000/svg}"


def half_moving(n_frames: int = 40) -> FaceAnimation:
    """A grid whose left half is still and whose right half waves; one extra triangle always faces away."""
    v, faces = grid(6)
    t = np.arange(n_frames)[:, None]
    frames = np.repeat(v[None], n_frames, axis=0)
    right = v[:, 0] > 0.01
    frames[:, right, 1] += 0.2 * np.sin(t / 4.0) * v[right, 0]
    back = np.array([[0, 0, -0.5], [0.2, 0, -0.5], [0, 0.2, -0.5]])  # clockwise seen from +z: a back face
    frames = np.concatenate([frames, np.repeat(back[None], n_frames, 0)[:, ::-1]], axis=1)
    faces = np.concatenate([faces, [[len(v), len(v) + 1, len(v) + 2]]]).astype(np.int32)
    return FaceAnimation(frames.astype(np.float32), faces, np.zeros(len(faces), np.int32),
                         (Part("skin", (0.8, 0.6, 0.5)),), 20.0, "half")


def sheet_of(anim, size=128):
    return extract.extract(anim, extract.fit_camera(anim, size), occlusion=False)


def paths(svg: bytes):
    return etree.fromstring(svg).findall(f".//{SVG}path")


def test_raw_writes_every_frame_with_two_decimals():
    anim = cube_animation(6)
    data = convert_animation(anim, ConversionOptions(size=64, raw=True, occlusion=False)).data
    for p in paths(data):
        values = p.find(f"{SVG}animate[@attributeName='d']").get("values").split(";")
        assert len(values) == anim.n_frames + 1  # every frame plus the held loop end
        assert all(re.fullmatch(r"M-?\d+\.\d\d,-?\d+\.\d\dL.*\d(Z)?", v) for v in values)  # open: no Z
    v = verify_animation(data, anim)
    assert v.ok and v.max_px <= 0.0071


def test_chapter_drops_hidden_coordinates_and_merges_still_runs():
    anim = half_moving()
    sheet = sheet_of(anim)
    raw = svg_anim.encode(sheet, ConversionOptions(), Report(), "raw")
    report = Report()
    chapter = svg_anim.encode(sheet, ConversionOptions(), report, "chapter")
    assert len(chapter) < 0.8 * len(raw)
    still = [p for p in paths(chapter) if p.find(f"{SVG}animate[@attributeName='d']") is None]
    assert len(still) >= 20  # the left half does not move: no coordinates animated at all
    v = verify_animation(chapter, anim)
    assert v.ok and v.max_px <= 0.0071  # exact to 2 decimals


def test_bounded_exact_is_small_static_shared_and_drops_never_visible():
    anim = half_moving()
    sheet = sheet_of(anim)
    assert not sheet.visible[:, -1].any()
    raw = svg_anim.encode(sheet, ConversionOptions(), Report(), "raw")
    data = svg_anim.write(sheet, ConversionOptions(exact=True), Report())
    assert len(data) < 0.3 * len(raw)
    ps = paths(data)
    ids = [p.get("id") for p in ps]
    assert f"f{anim.n_faces - 1}" not in ids and len(ids) == anim.n_faces - 1
    still = [p for p in ps if p.find(f"{SVG}animate") is None]
    assert len(still) >= 20
    # integers, relative, shortest: 'm' then implicit relative linetos, a minus sign as the separator
    assert all(re.fullmatch(r"m-?\d+[ -]\d+(?: ?-?\d+){4}z?", p.get("d")) for p in ps)  # open: no z
    classes = {p.get("class") for p in ps}
    assert len(classes) < len(ps) / 3  # fills shared through CSS classes
    root = etree.fromstring(data)
    w, vb = float(root.get("width")), [float(x) for x in root.get("viewBox").split()]
    assert vb[2] / w == viewbox_scale(0.25)
    v = verify_animation(data, anim)
    assert v.ok, v.summary()


def test_tighter_tolerance_costs_more_and_stays_within():
    anim = half_moving()
    sheet = sheet_of(anim)
    sizes = []
    for tol in (1.0, 0.25, 0.1):
        data = svg_anim.write(sheet, ConversionOptions(tolerance=tol), Report())
        assert verify_animation(data, anim).max_px <= tol
        sizes.append(len(data))
    assert sizes[0] < sizes[1] < sizes[2]


def test_colour_keys_stay_within_colour_tolerance():
    rng = np.random.default_rng(0)
    t = np.arange(60)[:, None, None]
    rgb = np.clip(0.5 + 0.3 * np.sin(t / rng.uniform(3, 20, (1, 25, 3))), 0, 1)
    active = rng.random((60, 25)) > 0.15
    keys = colours.color_keys(rgb, active, 3.0)
    shown = interpolate(keys)
    assert np.abs(shown - rgb * 255)[active].max() <= 3.0 + 1e-9
    assert np.all(keys.values == np.rint(keys.values))


def test_colour_keys_in_blocks_are_the_keys_in_one(monkeypatch):
    """color_keys works a block of paths at a time (memory): blocks of 4 paths give the keys of one block."""
    rng = np.random.default_rng(1)
    t = np.arange(50)[:, None, None]
    rgb = np.clip(0.5 + 0.4 * np.sin(t / rng.uniform(2, 30, (1, 23, 3))), 0, 1).astype(np.float32)
    rgb[:, :5] = rgb[:1, :5]  # static colours among the animated ones
    active = rng.random((50, 23)) > 0.2
    whole = colours.color_keys(rgb, active, 3.0)
    monkeypatch.setattr(freeknots, "BLOCK_TRACKS", 4)
    blocks = colours.color_keys(rgb, active, 3.0)
    assert whole.values.dtype == np.uint8 and whole.mask[:, 5:].sum() > 2 * 18  # keyed, not all static
    assert np.array_equal(whole.mask, blocks.mask) and np.array_equal(whole.values, blocks.values)
    assert np.abs(interpolate(blocks) - rgb * 255.0)[active].max() <= 3.0 + 1e-6


def _held(steps, t: int) -> np.ndarray:
    """The colour each path shows at frames 0..t-1: its last step's value (a brute-force reading)."""
    out = np.zeros((t,) + steps.values.shape[1:])
    for j in range(steps.mask.shape[1]):
        for k in range(t):
            out[k, j] = steps.values[np.flatnonzero(steps.mask[:k + 1, j])[-1], j]
    return out


def _fewest_steps(levels: np.ndarray, shown: np.ndarray, tol: float) -> int:
    """Fewest held colours within tol of one track's shown levels (T, 3): dynamic programming over cut points."""
    t = len(levels)
    best = [0] + [10**9] * t
    for b in range(1, t + 1):
        for a in range(b):
            sel = levels[a:b][shown[a:b]]
            if not len(sel) or (sel.max(axis=0) - sel.min(axis=0)).max() / 2 + 0.5 <= tol:
                best[b] = min(best[b], best[a] + 1)
    return best[t]


def test_colour_steps_hold_within_tolerance_with_the_fewest_steps():
    """color_steps: every shown frame within the tolerance of the held colour (integer levels), frame 0 always a
    step, a still shade one step, and no track split into more steps than the optimum (brute force)."""
    rng = np.random.default_rng(2)
    t = np.arange(40)[:, None, None]
    rgb = np.clip(0.5 + 0.3 * np.sin(t / rng.uniform(2, 15, (1, 12, 3))), 0, 1).astype(np.float32)
    rgb[:, :2] = rgb[5:6, :2]  # still shades
    active = rng.random((40, 12)) > 0.25
    active[:, 11] = np.arange(40) >= 30  # hidden until frame 30: its step at 0 holds the later colour
    steps = colours.color_steps(rgb, active, 3.0)
    assert steps.values.dtype == np.uint8 and steps.mask[0].all() and not steps.mask[40].any()
    held = _held(steps, 40)
    err = np.abs(held - rgb.astype(np.float64) * 255).max(axis=-1)
    assert err[active].max() <= 3.0
    assert (steps.mask.sum(axis=0)[:2] == 1).all() and steps.mask.sum() > 12 * 3
    assert steps.mask[:, 11].sum() == 1 + (steps.mask[31:40, 11].sum())  # no step while it is hidden
    for j in range(12):
        assert steps.mask[:, j].sum() == _fewest_steps(rgb[:, j].astype(np.float64) * 255, active[:, j], 3.0)
    # The report's colour error is the played one, exactly, whatever the block of paths.
    report_err = colours.color_error(rgb, active, steps)
    assert np.array_equal(np.sort(report_err), np.sort(err.T[active.T].astype(np.float32)))  # reported as float32


@pytest.mark.parametrize("seed", range(3))
def test_compiled_colour_steps_are_the_vectorised_ones_and_errors_the_played_ones(seed):
    rng = np.random.default_rng(seed)
    t, n = int(rng.integers(1, 80)), int(rng.integers(1, 30))
    rgb = np.clip(np.cumsum(rng.normal(0, 0.01, (t, n, 3)), axis=0) + rng.random((1, n, 3)), 0, 1)
    rgb = rgb.astype(np.float32)
    active = rng.random((t, n)) > rng.uniform(0, 0.8)
    tolerance = float(rng.uniform(0.3, 4))
    steps = colours.color_steps(rgb, active, tolerance)
    want = numpy_color_steps(rgb, active, tolerance)
    assert all(np.array_equal(a, b) for a, b in zip(steps, want))
    held = _held(steps, t)
    err = np.abs(held - rgb.astype(np.float64) * 255).max(axis=-1)
    got = colours.color_error(rgb, active, steps)
    assert np.array_equal(got, err.T[active.T].astype(np.float32))  # path by path


def numpy_color_steps(rgb, active, tolerance, paths=None):
    """colours.color_steps as it was before it was compiled: a loop over frames vectorised over paths."""
    t, p = active.shape
    mask = np.zeros((t + 1, p), bool)
    values = np.zeros((t + 1, p, 3), np.uint8)
    if not t or not p:
        return Keys(mask, values, np.full(p, -1))
    lo = np.full((p, 3), np.inf)
    hi = np.full((p, 3), -np.inf)
    start = np.zeros(p, np.int64)
    cols = np.arange(p)

    def hold(sel: np.ndarray) -> None:
        mid = np.where(np.isfinite(lo[sel]), (lo[sel] + hi[sel]) / 2, 0.0)
        mask[start[sel], cols[sel]] = True
        values[start[sel], cols[sel]] = np.clip(np.rint(mid), 0, 255).astype(np.uint8)

    for f in range(t):
        a = active[f]
        x = np.asarray(rgb[f] if paths is None else rgb[f, paths], np.float64) * 255
        nlo, nhi = np.minimum(lo, x), np.maximum(hi, x)
        cut = a & ((nhi - nlo).max(axis=1) / 2 + 0.5 > tolerance)  # frame f does not fit the held colour
        if cut.any():
            hold(np.flatnonzero(cut))
            start[cut] = f
        a3 = a[:, None]
        lo = np.where(cut[:, None], x, np.where(a3, nlo, lo))
        hi = np.where(cut[:, None], x, np.where(a3, nhi, hi))
    hold(cols)
    return Keys(mask, values, np.where(active.any(axis=0), np.argmax(active, axis=0), -1))


def test_colour_steps_and_errors_read_columns_of_the_sheet_without_a_copy():
    rng = np.random.default_rng(4)
    wide = rng.random((30, 14, 3)).astype(np.float32)  # the Sheet's face colours; the paths are some of its faces
    paths = np.array([9, 2, 13, 5, 0, 7])
    active = rng.random((30, 6)) > 0.3
    copy = colours.color_steps(wide[:, paths], active, 3.0)
    steps = colours.color_steps(wide, active, 3.0, paths)
    assert np.array_equal(steps.mask, copy.mask) and np.array_equal(steps.values, copy.values)
    assert steps.mask.sum() > 6 * 3  # random shades: many steps, so the comparison means something
    assert np.array_equal(colours.color_error(wide, active, steps, paths),
                          colours.color_error(wide[:, paths], active, copy))


def test_svg_colours_are_discrete_steps_that_play_within_the_tolerance():
    """In the exact file: paths animate their own colour with calcMode discrete; read back as a player does
    (each frame at k / T takes the last keyTime at or before it), every shown frame is within 3 levels."""
    anim = half_moving(30)
    rng = np.random.default_rng(4)
    sheet = sheet_of(anim)
    sheet = dataclasses.replace(sheet, face_rgb=np.clip(sheet.face_rgb + 0.05 * np.sin(
        np.arange(30)[:, None, None] / rng.uniform(1, 6, (1, sheet.face_rgb.shape[1], 3))), 0, 1).astype(np.float32))
    data = svg_anim.write(sheet, ConversionOptions(exact=True), Report())
    t = sheet.n_frames
    animated = 0
    for p in paths(data):
        tri = int(p.get("id")[1:])
        anims = p.findall(f"{SVG}animate[@attributeName='color']")
        shown = sheet.visible[:, tri]
        exact = sheet.face_colors(np.array([tri]))[:, 0].astype(np.float64) * 255
        if not anims:
            continue
        animated += 1
        assert anims[0].get("calcMode") == "discrete"
        times = np.array([float(x) for x in anims[0].get("keyTimes").split(";")])
        cols = np.array([[int(v[i:i + 2], 16) for i in (1, 3, 5)] for v in anims[0].get("values").split(";")])
        idx = np.searchsorted(times, np.arange(t) / t, side="right") - 1
        assert times[0] == 0 and np.abs(cols[idx] - exact)[shown].max() <= 3.0
    assert animated > 5


def test_colour_keys_extrapolated_past_black_stay_within_tolerance():
    """A shade that rises fast after a hidden start: the free key at 0 would lie below 0 and clipping it moved the
    first shown frames by 12 levels (the capture-like face at 256 px)."""
    t = np.arange(60)[:, None, None]
    rgb = np.clip((10 + 4.0 * (t - 40)) / 255 + 0.0 * np.ones((1, 2, 3)), 0, 1)
    rgb[:, 1] = 1 - rgb[:, 1]  # and one past white
    active = np.broadcast_to(t[:, :, 0] >= 40, (60, 2))
    keys = colours.color_keys(rgb, active, 3.0)
    assert np.abs(interpolate(keys) - rgb * 255)[active].max() <= 3.0 + 1e-9
    assert keys.values.min() >= 0 and keys.values.max() <= 255


def test_deterministic_and_svgz():
    anim = half_moving()
    a = convert_animation(anim, ConversionOptions(size=96, occlusion=False)).data
    b = convert_animation(anim, ConversionOptions(size=96, occlusion=False)).data
    assert a == b
    z = convert_animation(anim, ConversionOptions(size=96, occlusion=False, svgz=True))
    assert z.extension == ".svgz" and z.data[:2] == b"\x1f\x8b"
    assert verify_animation(gzip.decompress(z.data), anim).ok and verify_animation(z.data, anim).ok
    assert z.report.sizes["svg"] == len(gzip.decompress(z.data)) and z.report.sizes["output"] == len(z.data)


def test_key_texts_written_a_block_of_paths_at_a_time_are_the_same_file(monkeypatch):
    anim = half_moving()
    for opts in (ConversionOptions(size=96, occlusion=False), ConversionOptions(size=96, occlusion=False,
                                                                                max_animations=4)):
        one = convert_animation(anim, opts)
        monkeypatch.setattr(svg_anim, "KEY_TEXT_KEYS", 5)  # a path or two a block, some paths alone over it
        blocks = convert_animation(anim, opts)
        monkeypatch.undo()
        assert blocks.data == one.data and one.report.counts["keys"] > 5  # more than one block


def test_uniform_keys_fitted_a_block_of_paths_at_a_time_are_the_same_file(monkeypatch):
    # Evenly spaced keys are fitted for the paths of one key count together, in blocks of UNIFORM_VALUES track
    # values: a block of two paths writes the same file as all of them at once, and no fit sees more.
    anim = half_moving()
    fitted: list[int] = []
    fit = svg_anim.keyframes.uniform_fit
    monkeypatch.setattr(svg_anim.keyframes, "uniform_fit", lambda x, *a: fitted.append(x.shape[1]) or fit(x, *a))
    opts = ConversionOptions(size=96, occlusion=False, exact=True)  # merged paths are keyed together, not fitted
    one = convert_animation(anim, opts)
    assert max(fitted) > 2
    fitted.clear()
    monkeypatch.setattr(svg_anim, "UNIFORM_VALUES", anim.n_frames * 6 * 2)
    assert convert_animation(anim, opts).data == one.data
    assert max(fitted) == 2


def test_still_frame_is_static_and_exact_to_grid():
    anim = half_moving()
    data = convert_animation(anim, ConversionOptions(size=96, frame=7, occlusion=False)).data
    assert b"<animate" not in data and len(paths(data)) == anim.n_faces - 1


def test_raw_size_is_counted_exactly_without_writing(monkeypatch):
    rng = np.random.default_rng(4)
    track = rng.uniform(-150, 1500, (9, 7, 6))
    track[0, 0, 0] = -0.004  # rounds to zero: written and counted without a sign
    per_path = [";".join(svg_anim._raw_strings(track[:, j]) + svg_anim._raw_strings(track[-1:, j])) for j in range(7)]
    xy = track.reshape(9, 21, 2)  # every triangle its own three vertices
    assert svg_anim.raw_values_bytes(xy, np.arange(21).reshape(7, 3)) == sum(len(v) for v in per_path)
    # Shared vertices (a fan, one vertex in every triangle), some unused, counted in blocks of 4 vertices.
    corners = np.array([[0, 1 + j, 2 + j] for j in range(8)] + [[3, 0, 5]])
    xy = rng.uniform(-150, 1500, (9, 14, 2))
    tracks = [xy[:, c].reshape(9, 6) for c in corners]
    per_path = [";".join(svg_anim._raw_strings(tr) + svg_anim._raw_strings(tr[-1:])) for tr in tracks]
    monkeypatch.setattr(svg_anim, "RAW_COUNT_CELLS", 4 * 9)  # 9 frames: blocks of 4 vertices
    assert svg_anim.raw_values_bytes(xy, corners) == sum(len(v) for v in per_path)


def test_offsets_shorten_keys_only_where_they_pay():
    far = np.array([[1200 + k, -3400 - k, 1205 + k, -3394 - k, 1212 + k, -3386 - k] for k in range(30)])  # far away
    near = np.array([[3, 4, 5, 6, 7, 8], [4, 5, 5, 6, 7, 8]])  # two short keys: the attribute would cost more
    rows = np.concatenate([far, near])
    pk = np.array([0] * len(far) + [1] * len(near))
    off = offsets(rows, pk, 2)
    assert np.abs(off[0] - np.median(far[:, :2], axis=0)).max() <= 1 and off[1].tolist() == [0, 0]
    plain, moved = _path_strings(far), _path_strings(far, off[pk[: len(far)]])
    assert sum(map(len, moved)) < sum(map(len, plain)) - 30 * 4
    # The moved text plus its translate is the same triangle: parse both back.
    for a, b in zip(plain, moved):
        assert np.allclose(np.array(_triangles_of_d(a)), np.array(_triangles_of_d(b)) + np.tile(off[0], 3))



def test_hex_colours_are_python_s_lowercase_six_digits():
    rng = np.random.default_rng(3)
    levels = np.concatenate([[[0, 0, 0], [255, 255, 255], [0, 0, 15], [16, 0, 0]], rng.integers(0, 256, (500, 3))])
    want = [f"#{r:02x}{g:02x}{b:02x}" for r, g, b in levels.tolist()]
    assert svg_anim._hex(levels).tolist() == want
    assert svg_anim._hex(levels.astype(np.uint8)).tolist() == want  # narrow levels do not overflow the shifts
    assert svg_anim._hex(levels[:4].reshape(2, 2, 3)).tolist() == [want[:2], want[2:4]]
    assert svg_anim._hex(np.zeros((0, 3), np.int64)).tolist() == []
