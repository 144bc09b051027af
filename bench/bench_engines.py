"""Firefox ESR and WebKitGTK against Chromium (issue 18): every SVG output of the sample at three times.

The bundled sample, every frame, at SIZE px: the default flat SVG, static colours (--color-tolerance 255), merged
paths (static colours with --max-animations 60: paths of several triangles) and Gouraud (tests/engines.py
SVG_OUTPUTS). Each file is inlined in a page, paused at its first, middle and last frame time and screenshot in
headless Chromium (the reference, tests/svgrender.py), Firefox ESR (Marionette) and WebKitGTK (WebKitWebDriver
on Xvfb) (tests/engines.py; Debian's packages). Per engine: the smallest silhouette IoU to Chromium (alpha > 127)
and the largest mean colour difference where both are opaque, over the three times; seconds per frame (the page
load shared out, two screenshots per frame for Firefox and WebKit, which shoot over black and white to get
alpha back); and whether the player file (--to player) loads, with which renderer.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for path in (ROOT, ROOT / "tests"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from bench.playback import chromium, installed_engines
from converter import formats
from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.writers import player
from engines import (
    SVG_OUTPUTS,
    colour_difference,
    distances,
    over_white,
    player_frames,
    svg_frames,
)
from svgrender import chromium_frames, iou
from tests.conftest import SAMPLE

TITLE = "Firefox ESR and WebKitGTK draw the SVG like Chromium (issue 18)"
SIZE = 256
REPEATS = 3  # timed renders per file and engine (the first one's frames are compared)


def _timed(render) -> tuple[object, float]:
    """What render() returns the first time and the median seconds of REPEATS calls."""
    seconds, first = [], None
    for _ in range(REPEATS):
        t = time.perf_counter()
        out = render()
        seconds.append(time.perf_counter() - t)
        first = out if first is None else first
    return first, statistics.median(seconds)


def run() -> str:
    anim = formats.load(SAMPLE)
    sheet = extract(anim, fit_camera(anim, SIZE))
    n = len(anim.frames)
    keys = (0, n // 2, n - 1)
    times = [k / anim.fps for k in keys]
    files = {kind: write(sheet, ConversionOptions(size=SIZE, **kw), Report()) for kind, (write, kw) in SVG_OUTPUTS.items()}
    html = player.write(sheet, ConversionOptions(size=SIZE, to="player"), Report())
    rows, notes = [], []
    with chromium() as browser:
        reference, chromium_s = {}, {}
        for kind, data in files.items():
            reference[kind], s = _timed(lambda data=data: chromium_frames(browser, data, times, SIZE, SIZE))
            chromium_s[kind] = s / len(times)
    engines, missing = installed_engines("rows")
    notes += missing
    results: dict[tuple[str, str], str] = {}
    for name, launch in engines:
        t = time.perf_counter()
        with launch() as session:
            started = time.perf_counter() - t
            for kind, data in files.items():
                got, s = _timed(lambda data=data: svg_frames(session, data, times, SIZE, SIZE))
                ious = [iou(got[i, ..., 3] > 127, reference[kind][i, ..., 3] > 127) for i in range(len(times))]
                diffs = [colour_difference(got[i], reference[kind][i]) for i in range(len(times))]
                plays = (distances(got, reference[kind]).argmin(1) == np.arange(len(times))).all()
                results[(kind, name)] = (f"{min(ious):.4f} | {max(diffs):.2f} | {'yes' if plays else '**no**'} "
                                         f"| {s / len(times):.2f}")
            state, shots = player_frames(session, html, times)
            if state["state"] == "ready":
                svg = over_white(reference["flat"]).min(-1) < 250
                face = min(iou(shots[i].min(-1) < 250, svg[i]) for i in range(len(times)))
                player_note = f"plays ({state['renderer']}; its face's IoU to the flat SVG's, at least {face:.3f})"
            else:
                player_note = f"shows its message: {state['error']}"
            notes.append(f"{name}: started in {started:.1f} s; the player file {player_note}.")
    for kind in files:
        for name, _ in engines:
            rows.append(f"| {kind} | {len(files[kind]) / 1024:,.0f} | {name} | {results[(kind, name)]} "
                        f"| {chromium_s[kind]:.2f} |")
    return (
        f"The bundled sample ({n} frames at {anim.fps:g} fps) at {SIZE} px; times {', '.join(f'{t:.3f}' for t in times)} s "
        f"(frames {', '.join(map(str, keys))}). IoU = the smallest silhouette IoU to Chromium over the three times; "
        "colour = the largest mean RGB difference (8-bit levels) where both are opaque; plays = each of the engine's "
        "frames is nearest Chromium's at its own time (mean difference over white); s/frame = median of "
        f"{REPEATS} renders of the three times, page load included.\n\n"
        "| output | KB | engine | IoU min | colour max | plays | s/frame | Chromium s/frame |\n"
        "|---|---|---|---|---|---|---|---|\n"
        + "\n".join(rows) + "\n\n" + "\n".join(f"- {note}" for note in notes) + "\n"
    )


if __name__ == "__main__":
    print(run())
