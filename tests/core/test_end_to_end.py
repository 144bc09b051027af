"""End to end: bundled sample -> facesvg convert -> SVG in headless Chromium vs the pyrender frame."""

import json
import re
import weakref

import numpy as np
import pytest

from converter import convert as convert_module
from converter import formats, render
from converter.animation import vertex_normals
from converter.camera import Camera
from converter.convert import convert, extract_sheet
from converter.lighting import lambert
from converter.options import ConversionOptions, Report
from converter.outputs import output_kind
from svgrender import chromium_frame, iou


def metadata(svg: bytes) -> dict:
    m = re.search(rb'<metadata id="facesvg">(.*?)</metadata>', svg, re.S)
    from xml.sax.saxutils import unescape

    return json.loads(unescape(m.group(1).decode()))


@pytest.mark.browser
@pytest.mark.slow
def test_sample_silhouette_matches_prerender(browser, sample_path, artifacts):
    options = ConversionOptions(size=256)
    result = convert(sample_path, options)
    meta = metadata(result.data)
    cam = Camera.from_json(meta["camera"])
    anim = formats.load(sample_path)
    assert meta["frames"] == anim.n_frames and meta["fps"] == pytest.approx(anim.fps)
    picks = [0, anim.n_frames // 3, anim.n_frames // 2, (2 * anim.n_frames) // 3, anim.n_frames - 1]
    rgb = lambert(vertex_normals(anim.frames, anim.faces), anim.face_base_colors()[None], cam.view)
    refs = render.render_frames(anim.frames, anim.faces, rgb, cam, picks)
    scores = []
    for k in picks:
        svg_px = chromium_frame(browser, result.data, k / anim.fps, cam.width, cam.height)
        ref_mask = refs[k][..., 3] > 127
        svg_mask = svg_px[..., 3] > 127
        scores.append(iou(svg_mask, ref_mask))
        if k == picks[1]:
            from PIL import Image

            Image.fromarray(np.concatenate([svg_px, refs[k]], axis=1)).save(artifacts / "e2e_sample.png")
    assert min(scores) >= 0.97, f"silhouette IoU per frame {scores}"
    # The animation really moves: two frames differ.
    a = chromium_frame(browser, result.data, picks[0] / anim.fps, cam.width, cam.height)
    b = chromium_frame(browser, result.data, picks[2] / anim.fps, cam.width, cam.height)
    assert np.abs(a.astype(int) - b.astype(int)).sum() > 0


@pytest.mark.slow
def test_gltfpack_sample_every_part_visible_and_moving(tmp_path):
    """The gltfpack-style twin (quantized + meshopt, morph weights, head and eye rotations) converts fully."""
    from converter.verify import evaluate, verify_animation

    src = sample_path_gltfpack()
    anim = formats.load(src)
    result = convert(src, ConversionOptions(size=256))
    ev = evaluate(result.data)
    parts = anim.part_ids[ev.triangles]
    for pid, part in enumerate(anim.parts):
        mine = parts == pid
        assert mine.any(), f"no triangle of part {part.name} in the SVG"
        shown = ev.shown[:, mine]
        assert shown.any(axis=1).all(), f"part {part.name} disappears in some frame"
        # Moving: the drawn vertices of this part travel more than a pixel over the animation.
        travel = np.abs(ev.xy[:, mine] - ev.xy[:1, mine]).max()
        assert travel > 1.0, f"part {part.name} does not move ({travel:.3f} px)"
    check = verify_animation(result.data, anim)
    assert check.ok, check.summary()


def sample_path_gltfpack():
    from conftest import ROOT

    return ROOT / "samples" / "face_gltfpack.glb"


def test_per_vertex_colours_are_worked_out_only_for_gouraud_outputs(sample_path):
    anim = formats.load(sample_path).sliced(0, 6)
    flat = extract_sheet(anim, ConversionOptions(size=64), Report())
    smooth = extract_sheet(anim, ConversionOptions(size=64, shading="gouraud"), Report())
    assert flat.vertex_rgb is None and smooth.vertex_rgb.shape == (6, anim.n_vertices, 3)
    assert np.array_equal(flat.face_rgb, smooth.face_rgb) and np.array_equal(flat.xy, smooth.xy)


def test_flat_colours_are_stored_for_the_kept_triangles_only(sample_path):
    """The Sheet holds no colour for a triangle no frame shows (on the ICT head 24k of 51k, 1.1 GB at 4,000
    frames); the kept ones have the bits a colour for every triangle had."""
    import dataclasses

    from converter.extract import unit_face_normals
    from converter.lighting import lambert_linear, srgb_to_linear

    anim = formats.load(sample_path).sliced(0, 6)
    sheet = extract_sheet(anim, ConversionOptions(size=64), Report())
    kept = np.flatnonzero(sheet.kept)
    assert 0 < len(kept) < anim.n_faces and sheet.face_rgb.shape == (6, len(kept), 3)
    every = lambert_linear(unit_face_normals(anim.frames, anim.faces), srgb_to_linear(anim.triangle_colors()[None]),
                           sheet.camera.view)
    assert np.array_equal(sheet.face_colors(kept), every[:, kept])
    assert np.array_equal(sheet.face_colors(kept[::-1]), every[:, kept[::-1]])
    with pytest.raises(ValueError, match="never seen"):
        sheet.face_colors(np.flatnonzero(~sheet.kept)[:1])
    with pytest.raises(ValueError, match="kept"):
        dataclasses.replace(sheet, face_rgb=every)


def test_lighting_some_rows_gives_their_bits_among_all():
    from converter.camera import look_at
    from converter.lighting import lambert_linear

    rng = np.random.default_rng(4)
    normals = rng.normal(size=(5, 1001, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    rgb = rng.random((1, 1001, 3)).astype(np.float32)
    view = look_at(np.array([1.0, 2.0, 9.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    every = lambert_linear(normals, rgb, view)
    for rows in (np.arange(0, 1001, 3), np.array([1000, 7, 7, 0]), np.arange(1001)):
        got = lambert_linear(normals, rgb[:, rows], view, rows=rows)
        assert got.shape == (5, len(rows), 3) and np.array_equal(got, every[:, rows])


@pytest.mark.parametrize("end", [None, 8])  # the whole animation, and a frame range (prepare makes a new one)
def test_convert_lets_the_3d_frames_go_before_the_writer_runs(sample_path, monkeypatch, end):
    loaded, cut, alive = [], [], []
    real_load, real_cut, kind = convert_module.load, convert_module.prepare, output_kind("svg")
    real_write = kind.shading_writers["flat"]

    def load(*args, **kwargs):
        anim = real_load(*args, **kwargs)
        loaded.append(weakref.ref(anim.frames))
        return anim

    def prepare(anim, *args, **kwargs):
        out = real_cut(anim, *args, **kwargs)
        cut.append(weakref.ref(out.frames))
        return out

    def write(*args, **kwargs):
        alive.extend(ref() is not None for ref in loaded + cut)  # no gc.collect: freed by reference counting
        return real_write(*args, **kwargs)

    monkeypatch.setattr(convert_module, "load", load)
    monkeypatch.setattr(convert_module, "prepare", prepare)
    monkeypatch.setitem(kind.shading_writers, "flat", write)
    result = convert(sample_path, ConversionOptions(end=end))
    assert b"<svg" in result.data[:500]
    assert len(alive) == 2 and not any(alive)
