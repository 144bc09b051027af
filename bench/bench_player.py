"""The player output (issue 18, --to player): size next to the default SVG, write CPU, fidelity, playback fps.

For the bundled sample and the capture-like face (bench/capture_like.py), both at the default options: one
prepared animation and Sheet (convert.prepare + convert.extract_sheet, as convert_animation does), then the
registry's writers for `--to svg` (the default SVG) and `--to player`, each timed in CPU seconds
(time.process_time: every thread of this process). The player is checked by the verifier against the exact
projection, then opened as a document from a loopback server and played in headless Chromium (bench/playback.py
`measure`) at 1x / 4x / 6x CPU throttling; each cell is the median of RUNS runs. The Chromium flags are the
tests' (tests/conftest.py CHROMIUM_ARGS: --disable-gpu), under which WebGL runs on SwiftShader (software, in
the GPU process); the renderer the player picked is reported. A second row per face plays the same file with
multisampling off (the string `antialias: true` patched in the served copy), to show what SwiftShader's 4x MSAA
costs: a phone's GPU resolves it in hardware.
"""

from __future__ import annotations

import gzip
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.capture_like import capture_like
from bench.playback import THROTTLES, chromium, measure, serve
from converter import formats
from converter.convert import extract_sheet, prepare
from converter.options import ConversionOptions, Report
from converter.outputs import writer_for
from converter.verify import verify_animation
from tests.conftest import SAMPLE

TITLE = "Player output (--to player): size, write time and playback (issue 18)"
SECONDS = 5.0
RUNS = 3


def _written(sheet, options: ConversionOptions) -> tuple[bytes, float, Report]:
    """The registry writer's bytes for the options, its CPU seconds and report."""
    report = Report()
    t = time.process_time()
    data = writer_for(options)(sheet, options, report)
    return data, time.process_time() - t, report


def _gz(data: bytes) -> int:
    return len(gzip.compress(data, 9, mtime=0))


def _renderer(browser, url: str) -> str:
    page = browser.new_page()
    try:
        page.goto(url, wait_until="load")
        page.wait_for_function("() => window.facesvgPlayer && window.facesvgPlayer.state !== 'loading'",
                               timeout=120_000)
        return str(page.evaluate("() => facesvgPlayer.renderer || facesvgPlayer.error"))
    finally:
        page.close()


def _playback(browser, url: str, size: int) -> list[tuple[float, float, float]]:
    """Per throttling rate the medians of (fps rAF, fps changed, main ms per frame) over RUNS runs."""
    out = []
    for rate in THROTTLES:
        runs = [measure(browser, url, size, rate, SECONDS) for _ in range(RUNS)]
        out.append((statistics.median(r.fps_raf for r in runs), statistics.median(r.fps_changed for r in runs),
                    statistics.median(r.main_ms for r in runs)))
    return out


def _main_thread(browser, url: str, size: int) -> tuple[float, float]:
    """Main-thread task ms per second while playing at 1x, and the share of it spent in GLES2::ReadPixels (the
    software compositor's synchronous readback of the WebGL frame under --disable-gpu), from a 2 s trace."""
    page = browser.new_page(viewport={"width": size, "height": size})
    try:
        page.goto(url, wait_until="load")
        page.wait_for_function("() => window.facesvgPlayer && window.facesvgPlayer.state === 'ready'",
                               timeout=120_000)
        page.wait_for_timeout(500)
        browser.start_tracing(page=page, categories=["toplevel", "gpu", "cc"])
        page.wait_for_timeout(2000)
        events = json.loads(browser.stop_tracing())["traceEvents"]
    finally:
        page.close()
    main = {(e["pid"], e["tid"]) for e in events
            if e.get("name") == "thread_name" and e.get("args", {}).get("name") == "CrRendererMain"}

    spans = [e for e in events if e.get("ph") == "X" and (e["pid"], e["tid"]) in main]
    seconds = (max(e["ts"] + e.get("dur", 0) for e in spans) - min(e["ts"] for e in spans)) / 1e6 if spans else 1.0

    def ms_per_s(name: str) -> float:
        return sum(e.get("dur", 0) for e in spans if e.get("name") == name) / 1000 / seconds

    tasks = ms_per_s("ThreadControllerImpl::RunTask")
    return tasks, ms_per_s("GLES2::ReadPixels") / max(tasks, 1e-9)


def run() -> str:
    faces = (("bundled sample", formats.load(SAMPLE)), ("capture-like", capture_like()))
    size_rows, play_rows, trace_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        served = []
        for i, (label, anim) in enumerate(faces):
            svg_options, player_options = ConversionOptions(), ConversionOptions(to="player")
            prepared = prepare(anim, player_options, Report())
            sheet = extract_sheet(prepared, player_options, Report())
            svg, svg_cpu, _ = _written(sheet, svg_options)
            html, player_cpu, report = _written(sheet, player_options)
            v = verify_animation(html, prepared)
            size_rows.append(
                f"| {label} | {report.counts['paths']:,} | {report.counts['player_vertices']:,} "
                f"| {report.counts['keys']:,} | {len(html) / 1024:,.0f} / {_gz(html) / 1024:,.0f} "
                f"| {len(svg) / 1024:,.0f} / {_gz(svg) / 1024:,.0f} | {_gz(html) / _gz(svg):.2f} "
                f"| {player_cpu:.1f} / {svg_cpu:.1f} | {v.max_px:.3f} ({'OK' if v.ok else 'FAIL'}) |")
            (folder / f"p{i}.html").write_bytes(html)
            (folder / f"p{i}-noaa.html").write_bytes(html.replace(b"antialias: true", b"antialias: false", 1))
            served.append((label, sheet.camera.width))
        with serve(folder) as base, chromium() as browser:
            for i, (label, size) in enumerate(served):
                renderer = _renderer(browser, f"{base}/p{i}.html")
                busy, readback = _main_thread(browser, f"{base}/p{i}.html", size)
                trace_rows.append(f"| {label} | {busy:.0f} | {100 * readback:.0f}% |")
                for variant, name in (("", "default"), ("-noaa", "MSAA off")):
                    cells = _playback(browser, f"{base}/p{i}{variant}.html", size)
                    play_rows.append(
                        f"| {label} | {name} | {renderer} | " + " / ".join(f"{c[0]:.1f}" for c in cells)
                        + " | " + " / ".join(f"{c[1]:.1f}" for c in cells)
                        + " | " + " / ".join(f"{c[2]:.1f}" for c in cells) + " |")
    return (
        "Both faces at the default options (512 px, tolerance 0.25 px). Sizes in KB raw / gzip -9; write = CPU "
        "seconds of the writer alone (the Sheet is shared); max px = the verifier's largest deviation of a drawn "
        "vertex from the exact projection (tolerance 0.25 px).\n\n"
        "| face | paths | vertices | position keys | player KB / gzip | default SVG KB / gzip | player/SVG gzip "
        "| write CPU s player / SVG | player max px |\n|---|---|---|---|---|---|---|---|---|\n"
        + "\n".join(size_rows) + "\n\n"
        f"Playback of the player as a document, {SECONDS:.0f} s per run, median of {RUNS} runs per rate "
        "(1x / 4x / 6x CPU throttling); fps rAF = requestAnimationFrame callbacks per second, fps changed = "
        "screencast frames whose pixels changed, main ms = main-thread task time per frame (bench/playback.py). "
        "The machine (2 cores) was shared with other jobs while this ran: read the figures as a range.\n\n"
        "| face | variant | renderer | fps rAF 1x / 4x / 6x | fps changed | main ms/frame |\n"
        "|---|---|---|---|---|---|\n" + "\n".join(play_rows) + "\n\n"
        "Where the main thread's time goes while the player plays (default variant, 1x, a 2 s Chromium trace): "
        "busy = main-thread task ms per second; readback = the share of it inside GLES2::ReadPixels, where the "
        "software compositor (--disable-gpu) waits for SwiftShader to finish the WebGL frame and copies it back. "
        "The player's own script takes well under a millisecond per frame.\n\n"
        "| face | busy ms/s | readback |\n|---|---|---|\n" + "\n".join(trace_rows) + "\n"
    )


if __name__ == "__main__":
    print(run())
