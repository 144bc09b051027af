"""Rigid factoring through the whole conversion: verifier bound on composed positions, smaller files, same
pixels in Chromium as the plain encoding, deterministic bytes, odd inputs."""

from __future__ import annotations

import numpy as np
import pytest

from converter import verify
from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation
from converter.options import ConversionOptions
from tests.rigid.synth import captured_head
from tests.svgrender import chromium_frame


@pytest.fixture(scope="module")
def anim():
    return captured_head(n_frames=48)


@pytest.fixture(scope="module")
def outputs(anim):
    return {rigid: convert_animation(anim, ConversionOptions(size=192, occlusion=False, tolerance=0.25, rigid=rigid))
            for rigid in (True, False)}


def test_rigid_output_verifies_and_is_smaller(anim, outputs):
    rigid, plain = outputs[True], outputs[False]
    assert b"<animateTransform" in rigid.data and b"<animateTransform" not in plain.data
    assert rigid.report.counts["rigid_groups"] >= 1
    v = verify.verify_animation(rigid.data, anim)
    assert v.ok, v.summary()
    assert rigid.report.counts["paths"] == rigid.data.count(b"<path ") <= v.paths  # a merged path draws several
    assert len(rigid.data) < 0.8 * len(plain.data)


def test_head_group_wraps_every_path_and_bands_nest_inside(outputs):
    from lxml import etree

    root = etree.fromstring(outputs[True].data)
    ns = "{http://www.w3.org/2000/svg}"
    (head,) = [g for g in root if g.tag == f"{ns}g"]  # one top-level group: the head's
    assert head.find(f"{ns}animateTransform") is not None
    assert len(list(head.iter(f"{ns}path"))) == len(list(root.iter(f"{ns}path")))
    bands = [g for g in head if g.tag == f"{ns}g"]
    assert bands and all(g.find(f"{ns}animateTransform") is not None for g in bands)
    assert all(g.find(f"{ns}g") is None for g in bands)  # two levels, no more


def test_verifier_catches_a_wrong_group_transform(anim, outputs):
    data = outputs[True].data
    i = data.index(b'type="rotate"')
    j = data.index(b'values="', i) + len(b'values="')
    bad = data[:j] + b"3;" + data[j:]  # one extra rotate key: the played rotation is now off
    assert not verify.verify_animation(bad, anim).ok


def test_rigid_is_deterministic(anim, outputs):
    again = convert_animation(anim, ConversionOptions(size=192, occlusion=False, tolerance=0.25))
    assert again.data == outputs[True].data


def test_chromium_draws_rigid_like_plain(browser, outputs, artifacts):
    from PIL import Image

    for k in (5, 21, 40):
        t = k / 25.0
        a = _over_white(chromium_frame(browser, outputs[True].data, t, 192, 192))
        b = _over_white(chromium_frame(browser, outputs[False].data, t, 192, 192))
        diff = np.abs(a - b).max(axis=2)
        if (diff > 140).mean() > 0.0005:
            side_by_side = np.concatenate([a, b], axis=1).round().astype(np.uint8)
            Image.fromarray(side_by_side).save(artifacts / f"rigid_vs_plain_{k}.png")
        # Both are within 0.25 px of the exact projection, so at most 0.5 px apart: an anti-aliased edge pixel
        # may differ by up to half the contrast (128 levels against the transparent background), no more.
        assert (diff > 140).mean() < 0.0005, k
        assert diff.mean() < 1.0


def _over_white(rgba: np.ndarray) -> np.ndarray:
    alpha = rgba[..., 3:].astype(np.float64) / 255
    return rgba[..., :3] * alpha + 255 * (1 - alpha)


def test_tiny_inputs_do_not_crash():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]], np.int32)
    frames = np.stack([v + [0.01 * k, 0, 0] for k in range(6)])
    one = FaceAnimation(frames, faces, np.zeros(2, np.int32), (Part("skin", (0.8, 0.6, 0.5)),), 10.0)
    for a in (one, one.sliced(0, 1)):
        r = convert_animation(a, ConversionOptions(size=64, occlusion=False))
        assert r.data.startswith(b"<svg")
        if a is one:
            assert verify.verify_animation(r.data, a).ok
