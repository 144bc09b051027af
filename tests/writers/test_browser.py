"""The error-bounded SVG plays correctly in headless Chromium: frames match pyrender and the exact still."""

import numpy as np
import pytest

from converter import extract, formats, render
from converter.options import ConversionOptions, Report
from converter.writers import svg_anim
from svgrender import chromium_frame, iou


def pyrender_flat(anim, sheet, k):
    """pyrender's frame k with each triangle's flat Lambert colour (what the SVG paths carry)."""
    pr = render._pyrender()
    rgb = np.zeros((anim.n_faces, 3))  # a triangle never seen is hidden in every frame: any colour
    rgb[sheet.kept] = sheet.face_rgb[k]
    rgba = np.concatenate([np.round(rgb * 255), np.full((anim.n_faces, 1), 255)], 1).astype(np.uint8)
    with render.offscreen(sheet.camera.width, sheet.camera.height) as r:
        scene = render._scene(sheet.camera)
        scene.add(render._mesh(anim.frames[k], anim.faces, rgba, smooth=False))
        color, _ = r.render(scene, flags=pr.RenderFlags.FLAT | pr.RenderFlags.RGBA)
    return color


# Mean colour difference to the exact still: exact colours (tolerance 3 levels) vs the default static colours
# (one colour per triangle; the sample's shading changes by up to ~38 levels, 3.5 on average).
COLOUR_CASES = {3.0: 2.0, 8.0: 4.0, 255.0: 6.0}  # --exact, the default's shared colours, static colours (mobile)


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.parametrize("color_tolerance", COLOUR_CASES)
def test_animated_frames_match_pyrender_and_the_still(browser, sample_path, artifacts, color_tolerance):
    """Hidden triangles (collapsed in d) vanish and the played frames match the exact stills and pyrender."""
    anim = formats.load(sample_path).sliced(0, 48)
    sheet = extract.extract(anim, extract.fit_camera(anim, 192))
    size = sheet.camera.width
    data = svg_anim.write(sheet, ConversionOptions(size=192, color_tolerance=color_tolerance,
                                                   exact=color_tolerance == 3.0), Report())
    for k in (0, 17, 33, 47):
        played = chromium_frame(browser, data, k / anim.fps, size, size)
        still = svg_anim.write_still(sheet, ConversionOptions(size=192), Report(), k)
        exact = chromium_frame(browser, still, 0.0, size, size)
        ref = pyrender_flat(anim, sheet, k)
        mask_p, mask_e, mask_r = played[..., 3] > 127, exact[..., 3] > 127, ref[..., 3] > 127
        assert iou(mask_p, mask_e) >= 0.99
        assert iou(mask_p, mask_r) >= 0.97
        both = mask_p & mask_e
        diff = np.abs(played[..., :3].astype(int) - exact[..., :3].astype(int))[both]
        assert diff.mean() <= COLOUR_CASES[color_tolerance], f"frame {k}: mean colour difference {diff.mean():.2f}"
        inner = mask_p & mask_r
        dref = np.abs(played[..., :3].astype(int) - ref[..., :3].astype(int))[inner]
        assert np.median(dref) <= 4 + COLOUR_CASES[color_tolerance] - 2, f"frame {k}: median {np.median(dref)}"
        if k == 33:
            from PIL import Image

            Image.fromarray(np.concatenate([played, exact, ref], axis=1)).save(artifacts / "svg_anim_frames.png")
    # The animation moves: first and last frames differ.
    a = chromium_frame(browser, data, 0.0, size, size)
    b = chromium_frame(browser, data, 47 / anim.fps, size, size)
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 0.5
