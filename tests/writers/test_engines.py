"""Firefox ESR and WebKitGTK (Debian's packages) draw every SVG output like Chromium at the sampled times, and play
the player file (issue 18). tests/engines.py drives them; Chromium (tests/svgrender.py) is the reference."""

from __future__ import annotations

import re

import numpy as np
import pytest
from PIL import Image

from converter import formats
from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.writers import player
from engines import SVG_OUTPUTS, colour_difference, distances, over_white, player_frames, svg_frames
from svgrender import chromium_frames, iou

pytestmark = [pytest.mark.browser, pytest.mark.engines]

SIZE = 160
FRAMES = 40
KEYS = (0, FRAMES // 2, FRAMES - 1)  # first, middle and last frame
IOU_MIN = 0.99
# Mean colour difference to Chromium where both are opaque, 8-bit levels. Measured on these files (160 px, frames
# 0/20/39): Firefox 153 ESR 0.23-0.41 flat, 0.47-0.53 Gouraud; WebKitGTK 2.50 0.84-0.92 flat, 0.68 Gouraud. What
# differs is anti-aliasing where triangles meet (half the opaque pixels are equal, 90% within 2 levels), so one
# bound serves every output: 1.5, a 60% margin over WebKit, while one triangle in ten off by 15 levels fails it.
COLOUR_MAX = 1.5
# Frames 0, 20 and 39 differ from each other by 1.6-5.2 mean levels (over white), in every engine; an engine's frame
# is 0.1-0.5 from Chromium's at the same time. So MOVES, and the nearest-time check below, have wide margins.
MOVES = 0.5
# The player's face (non-white pixels) against the SVG's silhouette, measured: 0.994 in Firefox (canvas 2D: headless
# Firefox has no WebGL), 0.983-0.987 in WebKit (WebGL; measured when its triangles still grew by the SVG's half stroke).
PLAYER_IOU_MIN = 0.97

@pytest.fixture(scope="module")
def sample(sample_path):
    anim = formats.load(sample_path).sliced(0, FRAMES)
    return anim, extract(anim, fit_camera(anim, SIZE))


@pytest.fixture(scope="module")
def times(sample) -> list[float]:
    return [k / sample[0].fps for k in KEYS]


@pytest.fixture(scope="module")
def files(sample) -> dict[str, bytes]:
    return {kind: write(sample[1], ConversionOptions(size=SIZE, **kw), Report())
            for kind, (write, kw) in SVG_OUTPUTS.items()}


@pytest.fixture(scope="module")
def chromium(browser, files, times) -> dict[str, np.ndarray]:
    """Chromium's RGBA frames of every output at the sampled times: the reference."""
    return {kind: chromium_frames(browser, data, times, SIZE, SIZE) for kind, data in files.items()}


def _save(path, *rows: np.ndarray) -> None:
    """Frames side by side, one row per renderer, over white."""
    Image.fromarray(np.concatenate([np.concatenate(list(over_white(r)), 1) for r in rows], 0).astype(np.uint8)
                    ).save(path)


def _check(engine: str, kind: str, got: np.ndarray, ref: np.ndarray, times: list[float]) -> None:
    """An engine's RGBA frames at the times against Chromium's: silhouette, colour, and that it plays."""
    for i, t in enumerate(times):
        score = iou(got[i, ..., 3] > 127, ref[i, ..., 3] > 127)
        assert score >= IOU_MIN, f"{engine}, {kind}, t={t:.3f} s: silhouette IoU {score:.4f} to Chromium"
        diff = colour_difference(got[i], ref[i])
        assert diff <= COLOUR_MAX, f"{engine}, {kind}, t={t:.3f} s: mean colour difference {diff:.2f}"
    # It plays the animation: its frames differ from each other, and each is nearest Chromium's at its own time
    # (an engine that drew frame 0 at every time, or ignored keyTimes, fails here).
    moved, to_chromium = distances(got, got), distances(got, ref)
    for i in range(len(times)):
        for j in range(i + 1, len(times)):
            assert moved[i, j] > MOVES, f"{engine}, {kind}: frames at {times[i]:.3f} and {times[j]:.3f} s are the same"
        nearest = int(np.argmin(to_chromium[i]))
        assert nearest == i, (f"{engine}, {kind}: t={times[i]:.3f} s looks like Chromium's t={times[nearest]:.3f} s "
                              f"(mean differences {to_chromium[i].round(2).tolist()})")


@pytest.mark.parametrize("kind", SVG_OUTPUTS)
@pytest.mark.parametrize("engine", ["firefox", "webkit"])
def test_engine_draws_the_svg_like_chromium(request, engine, kind, files, chromium, times, artifacts):
    got = svg_frames(request.getfixturevalue(engine), files[kind], times, SIZE, SIZE)
    _save(artifacts / f"engines_{engine}_{kind.replace(' ', '_')}.png", got, chromium[kind])
    _check(engine, kind, got, chromium[kind], times)


def test_the_check_fails_on_a_file_that_does_not_play(firefox, files, chromium, times):
    """The same file with its animations removed (what an engine that ignores SMIL would draw) fails the check."""
    still = re.sub(rb"<animate[^>]*/>", b"", files["flat"])
    assert b"<animate" not in still
    with pytest.raises(AssertionError):  # its silhouette at the later times is frame 0's
        _check("firefox", "flat", svg_frames(firefox, still, times, SIZE, SIZE), chromium["flat"], times)


@pytest.mark.parametrize("engine", ["firefox", "webkit"])
def test_engine_plays_the_player(request, engine, sample, chromium, times, artifacts):
    html = player.write(sample[1], ConversionOptions(size=SIZE, to="player"), Report())
    state, got = player_frames(request.getfixturevalue(engine), html, times)
    assert state["state"] == "ready", f"{engine} shows the player's message: {state['error']}"
    ref = over_white(chromium["flat"])  # the SVG of the same conversion, on the player's white page
    Image.fromarray(np.concatenate([np.concatenate(list(got), 1), np.concatenate(list(ref), 1).astype(np.uint8)],
                                   0)).save(artifacts / f"engines_{engine}_player_{state['renderer']}.png")
    for i, t in enumerate(times):
        drawn, want = got[i].min(-1) < 250, ref[i].min(-1) < 250  # the face on the white page
        score = iou(drawn, want)
        assert score >= PLAYER_IOU_MIN, f"{engine} player ({state['renderer']}), t={t:.3f} s: IoU {score:.3f}"
    assert np.abs(got[0].astype(int) - got[-1].astype(int)).mean() > MOVES  # it moves
