"""Every SVG output shows frame 0 where SMIL is ignored (resvg, rsvg-convert, CairoSVG, Inkscape, thumbnailers).

The static attributes (group transforms, d, colour classes, display) must hold frame 0 as played, so a static
renderer draws what Chromium draws paused at t = 0. Renderers are compared at zoom 2: at 1x the anti-aliasing of
the 0.5 px seam strokes on small triangles differs between rasterisers (the 192 px synthetic head measures SSIM
0.986 resvg vs Chromium at 1x although its static attributes are exactly frame 0, 0.9975 at 2x); a head group
whose position lives only in its animation (the bug this guards against) measures 0.81 at 2x. resvg is a test
dependency; rsvg-convert and CairoSVG skip locally where missing and are required under CI (.ci/run installs them).
"""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image
from skimage.metrics import structural_similarity

from converter import formats, verify
from converter.convert import convert, convert_animation
from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.writers import svg_anim, svg_gouraud
from tests.rigid.synth import captured_head
from tests.svgrender import chromium_frame, iou

ZOOM = 2.0
MIN_SSIM = 0.99
STILL_FRAME = 3
CASES = ("sample", "exact", "gouraud", "still", "rigid", "mobile")
_ANIMATION = re.compile(rb"<(?:animate|animateTransform|animateMotion|set)\b[^>]*/>")


@pytest.fixture(scope="module")
def outputs(sample_path) -> dict[str, bytes]:
    rigid = convert_animation(captured_head(n_frames=48),
                              ConversionOptions(size=192, occlusion=False, tolerance=0.25, rigid=True))
    assert b"<animateTransform" in rigid.data  # the case needs rigid groups
    return {"sample": convert(sample_path, ConversionOptions()).data,  # shared colours: gradients
            "exact": convert(sample_path, ConversionOptions(exact=True)).data,
            "gouraud": convert(sample_path, ConversionOptions(shading="gouraud")).data,
            "still": convert(sample_path, ConversionOptions(frame=STILL_FRAME)).data,
            "rigid": rigid.data,
            "mobile": convert(sample_path, ConversionOptions(preset="mobile")).data}  # merged paths


def _size(svg: bytes) -> tuple[int, int]:
    w, h = re.search(rb'width="(\d+)" height="(\d+)"', svg).groups()
    return int(w), int(h)


def _png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))


def _resvg(svg: bytes) -> np.ndarray:
    import resvg_py

    return _png(bytes(resvg_py.svg_to_bytes(svg_string=svg.decode(), zoom=ZOOM)))


def _missing(why: str) -> None:
    """Skip locally; under CI every renderer must be there (.ci/run and the test extras install them)."""
    if os.environ.get("CI"):
        pytest.fail(f"{why}, but CI is set")
    pytest.skip(why)


def _rsvg(svg: bytes) -> np.ndarray:
    exe = shutil.which("rsvg-convert")
    if exe is None:
        _missing("rsvg-convert not installed (apt-get install librsvg2-bin)")
    return _png(subprocess.run([exe, "--zoom", str(ZOOM)], input=svg, capture_output=True, check=True).stdout)


def _cairosvg(svg: bytes) -> np.ndarray:
    try:
        import cairosvg
    except (ImportError, OSError):  # OSError: the package without libcairo
        _missing("CairoSVG (with libcairo) not installed (pip install cairosvg; apt-get install libcairo2)")
    return _png(cairosvg.svg2png(bytestring=svg, scale=ZOOM))


RENDERERS = {"resvg": _resvg, "rsvg-convert": _rsvg, "cairosvg": _cairosvg}


def _over_white(rgba: np.ndarray) -> np.ndarray:
    a = rgba[..., 3:4] / 255.0
    return rgba[..., :3] * a + 255 * (1 - a)


def _ssim(a: np.ndarray, b: np.ndarray) -> float:
    return float(structural_similarity(_over_white(a), _over_white(b), channel_axis=2, data_range=255))


@pytest.fixture(scope="module")
def chromium_t0(browser, outputs) -> dict[str, np.ndarray]:
    return {k: chromium_frame(browser, svg, 0.0, *_size(svg), scale=ZOOM) for k, svg in outputs.items()}


# Measured misses, kept visible (strict: each fails the suite once it passes). CairoSVG's black seams on the
# Gouraud file (SSIM 0.950: it read the gradients' axis animations as stops) are gone: none is left.
KNOWN_MISSES: dict[tuple[str, str], float] = {}


@pytest.mark.parametrize("renderer", RENDERERS)
@pytest.mark.parametrize("case", CASES)
def test_static_renderer_draws_frame_0_like_chromium(outputs, chromium_t0, artifacts, case, renderer, request):
    if (case, renderer) in KNOWN_MISSES:
        why = f"{renderer} draws {case} frame 0 at SSIM {KNOWN_MISSES[case, renderer]} < {MIN_SSIM} (issue 18)"
        request.applymarker(pytest.mark.xfail(strict=True, raises=AssertionError, reason=why))
    img = RENDERERS[renderer](outputs[case])
    ref = chromium_t0[case]
    assert img.shape == ref.shape
    score = _ssim(img, ref)
    if score < MIN_SSIM:
        Image.fromarray(np.concatenate([img, ref], axis=1)).save(artifacts / f"first_frame_{case}_{renderer}.png")
    assert score >= MIN_SSIM, f"{case}: {renderer} frame 0 SSIM {score:.4f} to Chromium at t = 0"


@pytest.mark.parametrize("case", ["sample", "still", "rigid", "mobile"])
def test_static_attributes_are_frame_0(outputs, case):
    """The verifier's reading of the file with every animation removed is its frame 0, exactly."""
    svg = outputs[case]
    played, static = verify.evaluate(svg), verify.evaluate(_ANIMATION.sub(b"", svg))
    np.testing.assert_array_equal(static.triangles, played.triangles)
    np.testing.assert_array_equal(static.shown[0], played.shown[0])
    shown = played.shown[0]
    np.testing.assert_allclose(static.xy[0][shown], played.xy[0][shown], atol=1e-6)


def test_gouraud_static_attributes_are_frame_0(browser, outputs, chromium_t0):
    """Gouraud (which the verifier does not read): Chromium draws the file without animations as at t = 0."""
    svg = outputs["gouraud"]
    static = chromium_frame(browser, _ANIMATION.sub(b"", svg), 0.0, *_size(svg), scale=ZOOM)
    assert np.abs(static.astype(int) - chromium_t0["gouraud"].astype(int)).max() <= 2


@pytest.mark.parametrize("case", CASES)
def test_hidden_triangles_use_display(outputs, case):
    """Inkscape draws visibility:hidden paths (black spikes) but honours display:none."""
    assert b"visibility" not in outputs[case]


@pytest.mark.slow
@pytest.mark.parametrize("shading", ["flat-raw", "gouraud"])
def test_display_animation_plays_like_the_still(browser, sample_path, shading):
    """The discrete display animation (raw flat, Gouraud) shows and hides triangles in Chromium as the stills."""
    anim = formats.load(sample_path).sliced(0, 48)
    sheet = extract(anim, fit_camera(anim, 192))
    writer, opts = ((svg_anim.write, dict(raw=True)) if shading == "flat-raw" else
                    (svg_gouraud.write, dict(shading="gouraud")))
    data = writer(sheet, ConversionOptions(size=192, **opts), Report())
    assert b'attributeName="display"' in data
    for k in (0, 17, 33, 47):
        played = chromium_frame(browser, data, k / anim.fps, 192, 192)
        still = chromium_frame(browser, writer(sheet, ConversionOptions(size=192, frame=k, **opts), Report()),
                               0.0, 192, 192)
        mask_p, mask_s = played[..., 3] > 127, still[..., 3] > 127
        assert iou(mask_p, mask_s) >= 0.99, f"frame {k}"
        both = mask_p & mask_s
        diff = np.abs(played[..., :3].astype(int) - still[..., :3].astype(int))[both]
        assert diff.mean() <= 2.0, f"frame {k}: mean colour difference {diff.mean():.2f} to the still"
