"""Our Lottie played by independent players (lottie-web's svg and canvas renderers, ThorVG through dotlottie-web)
against our SVG played by Chromium, at sampled frames: silhouettes (IoU) and colours inside both.

Also the transform mapping on its own: the SVG's stack ``translate rotate skewX scale`` with large angles against
the Lottie group transform the writer makes of it (p, r, sk = -skewX with sa 0, s in percent), in every player.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from conftest import SAMPLE
from converter.convert import convert_animation, extract_sheet, load, prepare
from converter.encode.groups import BandMotion, TransformAnim
from converter.options import ConversionOptions, Report
from converter.writers import lottie, svg_anim
from converter.writers.svg_transforms import group_open
from tests.reference import lottie as reference
from tests.reference.threejs import ALPHA, spread_frames
from tests.rigid.synth import captured_head
from tests.svgrender import chromium_frames, iou

pytestmark = [pytest.mark.browser, pytest.mark.slow]

MIN_IOU = 0.98
MAX_COLOUR = 4.0  # mean 8-bit levels inside both silhouettes


@pytest.fixture(scope="module")
def sample_files():
    """The sample's default SVG, Lottie and dotLottie, from one Sheet."""
    reference.require()
    options = ConversionOptions()
    anim = prepare(load(str(SAMPLE), options), options, Report())
    sheet = extract_sheet(anim, options, Report())
    data = lottie.write(sheet, options, Report())
    return svg_anim.write(sheet, options, Report()), data, lottie.package(data)


def _compare(browser, svg: bytes, doc: bytes, zipped: bytes, frames: list[int], artifacts=None, name: str = ""):
    """Per player the IoU and mean colour difference against the SVG at each frame."""
    anim = json.loads(doc)
    fps, w, h = anim["fr"], anim["w"], anim["h"]
    ours = chromium_frames(browser, svg, [f / fps for f in frames], w, h)
    out = {}
    for player in reference.PLAYERS:
        got = reference.lottie_frames(zipped if player == "thorvg" else doc, frames, player, browser=browser)
        rows = []
        for k, (a, b) in enumerate(zip(ours, got)):
            ma, mb = a[..., 3] > ALPHA, b[..., 3] > ALPHA
            both = ma & mb
            colour = float(np.abs(a[..., :3].astype(int) - b[..., :3].astype(int))[both].mean()) if both.any() else 255
            rows.append((iou(ma, mb), colour))
            if artifacts is not None and k == len(frames) // 2:
                Image.fromarray(np.concatenate([a, b], axis=1)).save(artifacts / f"lottie_{name}_{player}.png")
        out[player] = rows
    return out


def test_players_draw_the_sample_like_our_svg(browser, sample_files, artifacts):
    svg, doc, zipped = sample_files
    frames = spread_frames(json.loads(doc)["op"], 5)
    for player, rows in _compare(browser, svg, doc, zipped, frames, artifacts, "sample").items():
        for f, (i, c) in zip(frames, rows):
            assert i >= MIN_IOU and c <= MAX_COLOUR, (player, f, i, c)


def test_players_draw_rigid_groups_like_our_svg(browser):
    """A captured-like head whose plan has a head group and band groups inside it."""
    reference.require()
    anim = captured_head()
    options = ConversionOptions(size=192, occlusion=False)
    svg = convert_animation(anim, options).data
    result = convert_animation(anim, ConversionOptions(size=192, occlusion=False, to="lottie"))
    assert result.report.counts.get("rigid_groups", 0) >= 1
    doc = result.data
    frames = spread_frames(anim.n_frames, 5)
    for player, rows in _compare(browser, svg, doc, lottie.package(doc), frames).items():
        for f, (i, c) in zip(frames, rows):
            assert i >= MIN_IOU and c <= MAX_COLOUR, (player, f, i, c)


def test_transform_stack_maps_onto_lottie_transforms(browser):
    """Large rotate, skewX, non-uniform scale and translate, animated: each player against Chromium's SMIL."""
    reference.require()
    t, scale = 10, 4
    anims = (TransformAnim("translate", np.array([0, t]), np.array([[100.0, 90.0], [140.0, 110.0]]) * scale, 1),
             TransformAnim("rotate", np.array([0, t]), np.array([[30.0], [-25.0]]), 2),
             TransformAnim("skewX", np.array([0, t]), np.array([[20.0], [-15.0]]), 2),
             TransformAnim("scale", np.array([0, t]), np.array([[1.3, 0.8], [0.7, 1.2]]), 3))
    motion = BandMotion(np.zeros(2), anims, np.zeros((t, 2, 3)), 1.0, 4)
    rows = np.array([[-40, -30, 50, -20, 10, 45]]) * scale
    element = lottie.element_text([lottie.shape_text(rows, np.zeros(1, np.int64), True)], '{"a":0,"k":[1,0,0]}',
                                  "0", True)
    layer = lottie._layer([lottie._group([element], motion, t)], scale, t)
    doc = f'{{"v":"5.12.0","fr":10,"ip":0,"op":{t},"w":200,"h":200,"ddd":0,"assets":[],"layers":[{layer}]}}'.encode()
    assert reference.schema_errors(json.loads(doc)) == []
    d = "M{} {} L{} {} L{} {}z".format(*rows[0].tolist())
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {200 * scale} {200 * scale}" width="200" '
           f'height="200">{group_open(motion, t, "1s")}<path d="{d}" fill="#f00"/></g></svg>').encode()
    frames = [0, 3, 7]
    ours = chromium_frames(browser, svg, [f / 10 for f in frames], 200, 200)
    for player in reference.PLAYERS:
        got = reference.lottie_frames(json.loads(doc), frames, player, browser=browser)
        for f, a, b in zip(frames, ours, got):
            assert (b[..., 3] > ALPHA).sum() > 2000  # the triangle is drawn
            assert iou(a[..., 3] > ALPHA, b[..., 3] > ALPHA) >= 0.99, (player, f)
