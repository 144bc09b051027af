"""The player output (issue 18, --to player): size next to the default SVG, write CPU, fidelity, playback fps.

For the bundled sample and the capture-like face (bench/capture_like.py), both at the default options: one
prepared animation and Sheet (convert.prepare + convert.extract_sheet, as convert_animation does), then the
registry's writers for `--to svg` (the default SVG) and `--to player`, each timed in CPU seconds
(time.process_time: every thread of this process). The player is checked by the verifier against the exact
projection, then opened as a document from a loopback server and played in headless Chromium (bench/playback.py
`measure`) at 1x / 4x / 6x CPU throttling; each cell is the median of RUNS runs. The Chromium flags are the
tests' (tests/conftest.py CHROMIUM_ARGS: --disable-gpu), under which WebGL runs on SwiftShader (software, in
the GPU process); the renderer the player picked is reported.

Variants per face, each a copy of the same file with `window.facesvgPlayerOptions` set before the player's script:
the default (WebGL 2, multisampled unless a multisampled frame timed at start takes over 8 ms, and until frames
come late: more than 3 of the last 60 late, or the median of 30 below 45 fps; the share of runs that kept it and
the probe's ms are reported; a late switch falls inside the measured seconds), WebGL 2 with multisampling pinned on
and off, WebGL 1 pinned on (the script computes every frame's corners: the player before the GPU evaluation), and
the default without the start-up probe (its budget lifted: the late rule alone). A floor row plays a page that only clears a WebGL 2
canvas of the same size every frame: no WebGL player can beat it under these flags.
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


# Variants: (name, facesvgPlayerOptions or None for the file as written).
VARIANTS = (("default", None), ("WebGL 2, MSAA on", {"antialias": True}),
            ("WebGL 2, MSAA off", {"antialias": False}), ("WebGL 1 (script), MSAA on", {"renderer": "webgl",
                                                                                      "antialias": True}),
            ("default without the start-up probe (late rule only)", {"msaaBudgetMs": 1e9}))
_STATE = ("() => window.facesvgPlayer ? [facesvgPlayer.renderer, facesvgPlayer.antialias, facesvgPlayer.msaaProbeMs]"
          " : null")
FLOOR = """<!doctype html><html><body style="margin:0"><canvas id="c" width="{size}" height="{size}"></canvas><script>
const gl = document.getElementById("c").getContext("webgl2", {{antialias: true, depth: false}});
let k = 0;
function f() {{ k++; gl.clearColor((k % 60) / 60, 0.5, 0.5, 1); gl.clear(gl.COLOR_BUFFER_BIT);
  requestAnimationFrame(f); }}
requestAnimationFrame(f);
</script></body></html>"""


def _with_options(html: bytes, options: dict | None) -> bytes:
    """The player file with facesvgPlayerOptions set before its script runs."""
    if options is None:
        return html
    at = html.rindex(b"<script>")
    return html[:at] + b"<script>window.facesvgPlayerOptions = " + json.dumps(options).encode() + b";</script>" \
        + html[at:]


def _playback(browser, url: str, size: int) -> tuple[list[tuple[float, float, float, float]], list[str], list[str]]:
    """Per throttling rate the medians of (fps rAF, fps changed, main ms, script ms per frame) over RUNS runs, how
    many runs ended with multisampling on ("3/3"), and the median start-up probe ms ("-" where none ran)."""
    out, kept, probe = [], [], []
    for rate in THROTTLES:
        runs = [measure(browser, url, size, rate, SECONDS, state=_STATE) for _ in range(RUNS)]
        out.append((statistics.median(r.fps_raf for r in runs), statistics.median(r.fps_changed for r in runs),
                    statistics.median(r.main_ms for r in runs), statistics.median(r.script_ms for r in runs)))
        kept.append(f"{sum(bool(r.state and r.state[1]) for r in runs)}/{len(runs)}")
        ms = [r.state[2] for r in runs if r.state and r.state[2] is not None]
        probe.append(f"{statistics.median(ms):.1f}" if ms else "-")
    return out, kept, probe


def _row(label: str, name: str, renderer: str, cells, kept: list[str], probe: list[str]) -> str:
    return (f"| {label} | {name} | {renderer} | " + " / ".join(f"{c[0]:.1f}" for c in cells)
            + " | " + " / ".join(f"{c[1]:.1f}" for c in cells)
            + " | " + " / ".join(f"{c[2]:.1f}" for c in cells) + " | " + " / ".join(f"{c[3]:.1f}" for c in cells)
            + " | " + " / ".join(kept) + " | " + " / ".join(probe) + " |")


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
            for j, (_, opts) in enumerate(VARIANTS):
                (folder / f"p{i}-{j}.html").write_bytes(_with_options(html, opts))
            served.append((label, sheet.camera.width))
        size = served[-1][1]
        (folder / "floor.html").write_text(FLOOR.format(size=size))
        with serve(folder) as base, chromium() as browser:
            for i, (label, size) in enumerate(served):
                busy, readback = _main_thread(browser, f"{base}/p{i}-1.html", size)
                trace_rows.append(f"| {label} | {busy:.0f} | {100 * readback:.0f}% |")
                for j, (name, _) in enumerate(VARIANTS):
                    url = f"{base}/p{i}-{j}.html"
                    cells, kept, probe = _playback(browser, url, size)
                    play_rows.append(_row(label, name, _renderer(browser, url), cells, kept, probe))
            cells, _, _ = _playback(browser, f"{base}/floor.html", size)
            play_rows.append(_row(f"floor: an empty {size} px canvas", "cleared every frame", "webgl2", cells,
                                  ["-"] * len(cells), ["-"] * len(cells)))
    return (
        "Both faces at the default options (512 px, tolerance 0.25 px). Sizes in KB raw / gzip -9; write = CPU "
        "seconds of the writer alone (the Sheet is shared); max px = the verifier's largest deviation of a drawn "
        "vertex from the exact projection (tolerance 0.25 px).\n\n"
        "| face | paths | vertices | position keys | player KB / gzip | default SVG KB / gzip | player/SVG gzip "
        "| write CPU s player / SVG | player max px |\n|---|---|---|---|---|---|---|---|---|\n"
        + "\n".join(size_rows) + "\n\n"
        f"Playback of the player as a document, {SECONDS:.0f} s per run, median of {RUNS} runs per rate "
        "(1x / 4x / 6x CPU throttling); fps rAF = requestAnimationFrame callbacks per second, fps changed = "
        "screencast frames whose pixels changed, main ms = main-thread task time per frame, script ms = its "
        "JavaScript (the player's and the bench's own frame counter; bench/playback.py). "
        "The machine (2 cores) was shared with other jobs while this ran: read the figures as a range.\n\n"
        "Under --disable-gpu the compositor reads every WebGL frame back synchronously: even the empty canvas of "
        "the floor row costs the main thread several ms a frame (its main ms), which leaves little of a 60 fps "
        "frame at 4x (16.7 ms) for SwiftShader to draw the face in. On a phone the GPU composites the canvas "
        "without that readback.\n\n"
        "MSAA kept = runs that ended with multisampling on. The default (WebGL 2) times a multisampled frame 0 "
        "before showing the first frame (the median of 3 after one that compiles, each finished by a one-pixel "
        "read: probe ms, the median over the runs) and starts without multisampling when it takes over 8 ms, half "
        "a 60 Hz frame; later it drops it as soon as frames come late (more than 3 of the last 60 frames late, or "
        "the median of 30 below 45 fps; the frames before that count in its fps). The last variant is the default "
        "with the probe's budget lifted: the late rule alone, as before the probe.\n\n"
        "| face | variant | renderer | fps rAF 1x / 4x / 6x | fps changed | main ms/frame | script ms/frame "
        "| MSAA kept | probe ms |\n|---|---|---|---|---|---|---|---|---|\n" + "\n".join(play_rows) + "\n\n"
        "Where the main thread's time goes while the player plays (WebGL 2, MSAA on, 1x, a 2 s Chromium trace): "
        "busy = main-thread task ms per second; readback = the share of it inside GLES2::ReadPixels, where the "
        "software compositor (--disable-gpu) waits for SwiftShader to finish the WebGL frame and copies it back. "
        "With WebGL 2 the player's script sets two uniforms a frame.\n\n"
        "| face | busy ms/s | readback |\n|---|---|---|\n" + "\n".join(trace_rows) + "\n"
    )


if __name__ == "__main__":
    print(run())
