"""Playback in Chromium (issue 18): frames per second under CPU throttling, as a document and as <img>.

Files: the bundled sample (default, static colours, mobile preset) and the capture-like face (default, static
colours, the mobile preset, the mobile preset without merging paths (--max-animations off) and with exact
colours). Gouraud is left out to keep the section near ten minutes (its 5 MB sample file alone loads for
minutes at 6x). Each is opened from a loopback server as a document and inside an <img>, at 1x, 4x and 6x CPU
throttling (DevTools Emulation.setCPUThrottlingRate: 4x and 6x stand in for a mid-range and a low-end phone).
The mobile-preset capture rows are the median of REPEATS runs per cell, the others one run. Files whose
predicted class is "heavy" play as a document at 1x only, given HEAVY_LOAD_SECONDS to show a frame: the
exact-colour capture kept a renderer busy for over 20 minutes at 4x without finishing.
"""

from __future__ import annotations

import gzip
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.capture_like import capture_like
from bench.playback import THROTTLES, chromium, host_page, measure, serve
from converter.convert import convert, convert_animation
from converter.options import PRESETS, ConversionOptions, Report
from converter.playcost import HEAVY, playback_class
from tests.conftest import SAMPLE

TITLE = "Playback in Chromium under CPU throttling (issue 18)"
SECONDS = 3.0
REPEATS = 3
HEAVY_LOAD_SECONDS = 120.0  # a file predicted heavy plays only at 1x, and only if it shows a frame by then
MOBILE = {"preset": "mobile"}
# Options equal to a default would take the preset's value, so the variants spell the preset out.
STATIC_COLOURS = {"color_tolerance": 255.0}  # the default options but one static colour per triangle
UNMERGED = {k: v for k, v in PRESETS["mobile"].values.items() if k != "max_animations"}
EXACT_COLOURS = {k: v for k, v in UNMERGED.items() if k != "color_tolerance"}


def outputs() -> list[tuple[str, bytes, int, Report, int]]:
    """(label, svg bytes, viewport px, report, runs per cell) for every file measured."""
    out = []
    for label, opts in (("sample, default (exact colours)", {}), ("sample, static colours", STATIC_COLOURS),
                        ("sample, mobile preset", MOBILE)):
        options = ConversionOptions(**opts)
        result = convert(SAMPLE, options)
        out.append((label, result.data, options.size, result.report, 1))
    anim = capture_like()
    for label, opts, runs in (("capture-like, mobile preset", MOBILE, REPEATS),
                              ("capture-like, mobile preset, paths not merged", UNMERGED, REPEATS),
                              ("capture-like, mobile preset, not merged, exact colours", EXACT_COLOURS, 1),
                              ("capture-like, default (exact colours)", {}, 1),
                              ("capture-like, static colours", STATIC_COLOURS, 1)):
        options = ConversionOptions(**opts)
        result = convert_animation(anim, options)
        out.append((label, result.data, options.size, result.report, runs))
    return out


def _median(browser, url: str, size: int, rate: float, runs: int, load_seconds: float):
    """The run with the median rAF fps of `runs` runs (None: no frame within load_seconds)."""
    cells = [measure(browser, url, size, rate, SECONDS, load_seconds) for _ in range(runs)]
    if any(c is None for c in cells):
        return None
    return sorted(cells, key=lambda c: c.fps_raf)[len(cells) // 2]


def _cells(cells: list, field: str, digits: int) -> str:
    return " / ".join("-" if c is None else f"{getattr(c, field):.{digits}f}" for c in cells)


def _colour(report: Report) -> str:
    f = report.figures
    if "color_error_max_levels" not in f:
        return "exact"
    return f"{f['color_error_max_levels']:.0f} / {f['color_error_p99_levels']:.0f}"


def run() -> str:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        files = outputs()
        for i, (_, data, size, _, _) in enumerate(files):
            (folder / f"f{i}.svg").write_bytes(data)
            (folder / f"f{i}.html").write_text(host_page(f"f{i}.svg", size))
        with serve(folder) as base, chromium() as browser:
            for i, (label, data, size, report, runs) in enumerate(files):
                paths = len(re.findall(rb"<path", data))
                animated = len(re.findall(rb"<animate\b", data))
                ms = report.figures.get("playback_ms_4x")
                predicted = f"{ms:.0f} ({playback_class(ms)})" if ms is not None else "-"
                heavy = ms is not None and playback_class(ms) == HEAVY
                modes = (("document", f"{base}/f{i}.svg"),) + (() if heavy else (("<img>", f"{base}/f{i}.html"),))
                rates = THROTTLES[:1] if heavy else THROTTLES
                for mode, url in modes:
                    cells = [_median(browser, url, size, rate, runs, HEAVY_LOAD_SECONDS if heavy else 300.0)
                             for rate in rates]
                    cells += [None] * (len(THROTTLES) - len(cells))
                    shown = [c for c in cells if c is not None]
                    rows.append(
                        f"| {label} | {paths:,} / {animated:,} | {len(data) / 1024:,.0f} / "
                        f"{len(gzip.compress(data, 9, mtime=0)) / 1024:,.0f} | {_colour(report)} | {mode} | "
                        f"{_cells(cells, 'fps_raf', 1)} | {_cells(cells, 'fps_changed', 1)} | "
                        f"{_cells(cells, 'main_ms', 0)} | {predicted} | "
                        + (f"{shown[0].first_frame_ms:,.0f} | {max(c.renderer_mb for c in shown):,.0f} |" if shown
                           else f"no frame in {HEAVY_LOAD_SECONDS:.0f} s | - |"))
                    print(rows[-1], flush=True)
    head = (
        f"Each cell: {SECONDS:.0f} s of playback after load at one throttling rate (1x / 4x / 6x); the "
        f"mobile-preset capture rows take the median of {REPEATS} runs per cell, the others one run; files "
        f"predicted heavy play as a document at 1x only, if they show a frame within {HEAVY_LOAD_SECONDS:.0f} s. A 2-core machine, possibly shared with other jobs "
        "(single runs scatter by about +-40 %). paths / animations = `<path>` "
        "and `<animate>` elements; colour error = max / 99th percentile 8-bit levels of the played flat colours "
        "against the exact shade (animated paths count their tolerance); fps rAF = requestAnimationFrame "
        "callbacks per second; fps changed = screencast frames whose pixels changed per second (inside `<img>` "
        "the host page's rAF overstates playback); main ms = main-thread task time per rAF frame "
        "(Performance.getMetrics TaskDuration); predicted = converter.playcost's ms per frame at 4x and its "
        "class; first frame = navigation start to the first animation frame after load, at 1x; renderer MB = "
        "resident memory of the renderer processes.\n\n"
        "| output | paths / animations | KB / gzip KB | colour error | as | fps rAF 1x / 4x / 6x | fps changed "
        "| main ms/frame | predicted ms at 4x | first frame ms | renderer MB |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    return head + "\n".join(rows) + "\n"
