"""Rendered Gouraud stills against the pyrender prerender of the same camera and lights (resvg and Chromium).

Thresholds, measured on this 320-triangle egg at 128 px (vertex colours from converter.lighting): the flat
writer scores SSIM 0.78 against the smooth prerender, the exact method 0.975 and the chapter method 0.95-0.96
in both resvg and Chromium. What is left is silhouette anti-aliasing (pyrender's 4x MSAA vs analytic
coverage), a large share of a small image. The floors (0.96 exact, 0.93 chapter) keep ~0.01-0.02 of room for
renderer anti-aliasing changes while a lost gradient, a shifted feImage or flat colours fall far below (the
chapter method with an offset feImage measured 0.80). Colour-space mistakes are caught by the interior
colour test below, not by SSIM. On the 512 px face the bench measures the issue's target (>= 0.98).
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage
from skimage.metrics import structural_similarity

from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.writers import svg_anim, svg_gouraud
from tests.gouraud.meshes import ellipsoid
from tests.svgrender import chromium_frame

SIZE = 128
FRAME = 1
MIN_SSIM = {"gouraud": 0.96, "gouraud-chapter": 0.93}
FLAT_MARGIN = 0.1


@pytest.fixture(scope="module")
def subject():
    anim = ellipsoid(n_frames=3, subdivisions=2)
    sheet = extract(anim, fit_camera(anim, SIZE), reference_frames=(FRAME,))
    stills = {s: (svg_anim.write if s == "flat" else svg_gouraud.write)(
        sheet, ConversionOptions(shading=s, frame=FRAME), Report()) for s in ("flat", "gouraud", "gouraud-chapter")}
    return sheet, sheet.references[FRAME], stills


def resvg(svg: bytes, zoom: float = 1.0) -> np.ndarray:
    import resvg_py

    png = bytes(resvg_py.svg_to_bytes(svg_string=svg.decode(), zoom=zoom))
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))


def ssim(img: np.ndarray, ref: np.ndarray) -> float:
    a = img[..., :3] * (img[..., 3:4] / 255.0)
    b = ref[..., :3] * (ref[..., 3:4] / 255.0)
    return float(structural_similarity(a, b, channel_axis=2, data_range=255))


def interior(ref: np.ndarray, zoom: int = 1) -> np.ndarray:
    inside = ndimage.binary_erosion(ref[..., 3] > 0, iterations=2)
    return np.kron(inside, np.ones((zoom, zoom), bool)) if zoom > 1 else inside


def test_resvg_matches_the_prerender(subject, artifacts):
    sheet, ref, stills = subject
    flat = ssim(resvg(stills["flat"]), ref)
    for shading, floor in MIN_SSIM.items():
        img = resvg(stills[shading])
        Image.fromarray(img).save(artifacts / f"gouraud_{shading}_resvg.png")
        score = ssim(img, ref)
        assert score >= floor, (shading, score)
        assert score >= flat + FLAT_MARGIN, (shading, score, flat)


def test_exact_colours_match_inside_the_silhouette(subject):
    # Same colour space on both sides: interior pixels agree to a few 8-bit levels (GL's perspective-correct
    # interpolation and 8-bit stops are the only differences); a linearRGB mix-up would be off by tens.
    _, ref, stills = subject
    img = resvg(stills["gouraud"]).astype(float)
    inside = interior(ref)
    diff = np.abs(img[..., :3] - ref[..., :3].astype(float)).max(axis=-1)[inside]
    assert np.median(diff) <= 1.0 and np.percentile(diff, 99) <= 6.0


@pytest.mark.parametrize("zoom", [1, 2])
def test_no_cracks_between_neighbours(subject, zoom):
    # Page showing through seams: pixels inside the silhouette less than 98% opaque. Without the still's
    # underlay this egg has 322 such pixels at 1x (the 1 px stroke alone leaves 2-8% gaps on diagonals).
    _, ref, stills = subject
    img = resvg(stills["gouraud"], zoom)
    leaks = (img[..., 3] < 250) & interior(ref, zoom)
    assert leaks.sum() == 0, leaks.sum()


def test_chromium_matches_the_prerender(subject, browser, artifacts):
    _, ref, stills = subject
    flat = ssim(chromium_frame(browser, stills["flat"], 0, SIZE, SIZE), ref)
    for shading, floor in MIN_SSIM.items():
        img = chromium_frame(browser, stills[shading], 0, SIZE, SIZE)
        Image.fromarray(img).save(artifacts / f"gouraud_{shading}_chromium.png")
        score = ssim(img, ref)
        assert score >= floor, (shading, score)
        assert score >= flat + FLAT_MARGIN, (shading, score, flat)


def test_chromium_animation_at_a_frame_matches_the_still(subject, browser):
    sheet, _, stills = subject
    anim = svg_gouraud.write(sheet, ConversionOptions(shading="gouraud", raw=True), Report())
    moving = chromium_frame(browser, anim, FRAME / sheet.fps, SIZE, SIZE).astype(float)
    still = chromium_frame(browser, stills["gouraud"], 0, SIZE, SIZE).astype(float)
    # Same pixels up to edge anti-aliasing where the animation's painter order differs from the still's.
    assert np.median(np.abs(moving - still)) == 0 and np.mean(np.abs(moving - still) > 8) < 0.02
