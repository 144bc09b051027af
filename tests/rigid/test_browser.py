"""Chromium plays the group transform stack (animateTransform translate/rotate/skewX/scale, additive sum) the
way the numpy evaluation (and so the verifier) says."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from converter.encode import groups
from converter.writers.svg_transforms import group_open
from tests.svgrender import chromium_frame, iou

SIZE = 200
FRAMES = 20
FPS = 10.0


def _motion(scale: int) -> groups.BandMotion:
    k = np.arange(FRAMES) / FRAMES
    params = np.column_stack([100 + 30 * np.sin(2 * np.pi * k), 100 + 20 * np.cos(2 * np.pi * k),
                              60 * np.sin(2 * np.pi * k), 15 * np.sin(4 * np.pi * k),
                              1 + 0.3 * np.sin(2 * np.pi * k), 1 - 0.25 * np.sin(2 * np.pi * k)])
    return groups.band_motion(params, np.zeros(2), 60.0, 0.05, scale, kt_decimals=4)


def test_chromium_plays_the_transform_stack(browser, artifacts):
    scale = 4
    motion = _motion(scale)
    assert [a.kind for a in motion.anims] == ["translate", "rotate", "skewX", "scale"]
    local = np.array([[-50.0, -30.0], [55.0, -10.0], [-20.0, 45.0]])  # px, relative to the band origin
    d = "M{} {}L{} {}L{} {}z".format(*np.rint(local * scale).astype(int).reshape(-1).tolist())
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {SIZE * scale} {SIZE * scale}" width="{SIZE}" '
           f'height="{SIZE}">{group_open(motion, FRAMES, f"{FRAMES / FPS:g}s")}'
           f'<path d="{d}" fill="#000"/></g></svg>').encode()
    worst = 1.0
    for k in (0, 3, 7, 12, 18):
        img = chromium_frame(browser, svg, k / FPS, SIZE, SIZE)
        got = img[..., 3] > 127
        m = motion.matrices[k]
        pts = local @ m[:, :2].T + m[:, 2]
        ref = Image.new("L", (SIZE, SIZE), 0)
        ImageDraw.Draw(ref).polygon([tuple(p) for p in (pts - 0.5).tolist()], fill=255)  # PIL: centres at ints
        score = iou(got, np.asarray(ref) > 127)
        worst = min(worst, score)
        if score < 0.93:
            Image.fromarray(img).save(artifacts / f"rigid_stack_{k}.png")
        # The coverage-weighted centroid of the drawn pixels is the triangle's centroid where the matrices put it.
        alpha = img[..., 3].astype(np.float64)
        ys, xs = np.mgrid[0:SIZE, 0:SIZE] + 0.5
        centre = np.array([(alpha * xs).sum(), (alpha * ys).sum()]) / alpha.sum()
        assert np.abs(centre - pts.mean(axis=0)).max() < 0.15, (k, centre, pts.mean(axis=0))
    assert worst > 0.93  # shape (PIL and Skia differ on edge pixels); the centroid check is the precise one
