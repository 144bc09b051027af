"""`--to puppet`: building a face's 2D puppet, its package size and what a take costs a frame.

Faces: the tests' generated face (tests/puppet/faces.py), and where ../shared/data exists the ICT FaceKit head and
the Ready Player Me avatar, each with the real Live Link Face take (livelinkface_MySlate_3.csv) embedded and a
4,000-frame take of the same 61 columns. Build CPU is the puppet stage and the writer (loading the face and the
capture is the loaders' cost, shown apart); the package is the HTML without a take, raw and gzipped. Playback
(issue 52): each face with the Live Link Face take playing, rAF fps in Chromium (1x, 4x), Firefox ESR and WebKitGTK;
and the CPU a frame costs Chromium's threads (from /proc), which a loaded machine blurs less than fps.
"""

from __future__ import annotations

import gzip
import os
import sys
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_weights import write_capture
from bench.playback import installed_engines
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions, Report
from converter.puppet import from_track, puppet_of
from converter.writers import puppet as writer
from tests.conftest import chromium_path, launched_chromium
from tests.puppet.faces import face_zip
from tests.reference import threejs

TITLE = "Puppet (--to puppet): build time, package size, bytes per take frame"
SHARED = ROOT.parent / "shared" / "data"
ICT = SHARED / "ict_facekit"
RPM = SHARED / "real" / "rpm_template_xr.glb"
LLF = SHARED / "real" / "livelinkface_MySlate_3.csv"
LONG_FRAMES = 4000
THROTTLE = 4  # DevTools CPU throttling, as bench_playback's mid-range phone
DRAWS = 60
SWEEP = (0, 10, 20, 30, 40, 50)  # degrees of head yaw, then pitch, against our prerender
SWEEP_SIZE = 256
IN_VIEW = 0.5  # below this share of its rest silhouette the prerendered head has left the frame
# One frame of the take after another, each evaluated and drawn at once: the script's CPU time a frame.
DRAW_LOOP = """async (n) => {
  await new Promise((r) => requestAnimationFrame(() => r()));
  const t0 = performance.now();
  for (let i = 0; i < n; i++) puppet.seek((i % 97) / 97 * Math.max(puppet.duration, 0.01));
  return (performance.now() - t0) / n;
}"""
WARM_S, PLAY_S = 1.0, 5.0  # the take plays this long before rAF is counted over PLAY_S (as bench/playback.py)
# rAF callbacks and frames the puppet drew over `secs` after `warm` seconds of play; `done` gets the counts.
_FPS_BODY = """setTimeout(() => {
  let n = 0, t0 = null, t1 = null;
  const f0 = puppet.frames;
  const tick = (t) => {
    if (t0 === null) t0 = t; else { n++; t1 = t; }
    if (t1 !== null && t1 - t0 >= secs * 1000)
      done({n, dt: t1 - t0, drawn: puppet.frames - f0, renderer: puppet.renderer, playing: puppet.playing});
    else requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}, warm * 1000);"""
FPS_PAGE = "([warm, secs]) => new Promise((done) => {" + _FPS_BODY + "})"  # Playwright
FPS_SESSION = "const [warm, secs, done] = arguments;" + _FPS_BODY  # WebDriver / Marionette


def _paused_pages(pages: list[bytes]) -> Iterator[object]:
    """Each puppet page loaded paused in headless Chromium (a Playwright page, closed after its turn); nothing
    without Chromium."""
    exe = chromium_path()
    if not exe:
        return
    with launched_chromium(exe) as browser, tempfile.TemporaryDirectory() as tmp:
        for k, data in enumerate(pages):
            path = Path(tmp) / f"p{k}.html"
            path.write_bytes(data)
            page = browser.new_page(viewport={"width": 1024, "height": 800})
            page.goto(path.as_uri() + "?paused")
            page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=120000)
            yield page
            page.close()


def draw_ms(pages: list[bytes]) -> list[tuple[float, float, str]]:
    """(ms a frame unthrottled, at THROTTLE x, renderer) of each page in headless Chromium, or [] without it."""
    out = []
    for page in _paused_pages(pages):
        page.evaluate("() => puppet.pause()")
        plain = page.evaluate(DRAW_LOOP, DRAWS)
        cdp = page.context.new_cdp_session(page)
        cdp.send("Emulation.setCPUThrottlingRate", {"rate": THROTTLE})
        slow = page.evaluate(DRAW_LOOP, DRAWS)
        out.append((plain, slow, page.evaluate("() => puppet.renderer")))
    return out


# One take frame after another, each evaluated, drawn and finished (gl.finish): the CPU the browser's threads spend a
# frame, read from /proc around the loop (more robust than fps on a loaded machine).
FINISH_LOOP = """(n) => { const T = Math.max(puppet.duration, 0.01), c = document.getElementById('puppet-canvas');
  const gl = puppet.renderer.startsWith('webgl') ? (c.getContext('webgl2') || c.getContext('webgl')) : null;
  for (let i = 0; i < n; i++) { puppet.seek((i % 97) / 97 * T); if (gl) gl.finish(); }
}"""
CPU_FRAMES = 200
CPU_COLUMNS = ("renderer main", "GPU main", "GL raster", "other")


def _chromium_cpu() -> Counter:
    """CPU seconds so far of each thread of the Chromium processes under this one, by CPU_COLUMNS group."""
    tick = os.sysconf("SC_CLK_TCK")
    children: dict[int, list[int]] = defaultdict(list)
    for d in os.listdir("/proc"):
        try:
            children[int(Path(f"/proc/{d}/stat").read_text().rsplit(")", 1)[1].split()[1])].append(int(d))
        except (OSError, ValueError, IndexError):
            continue
    out: Counter = Counter()
    todo = list(children[os.getpid()])
    while todo:
        pid = todo.pop()
        todo += children[pid]
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        if "chrom" not in cmd.split(" ", 1)[0]:
            continue
        kind = "renderer" if "--type=renderer" in cmd else "gpu" if "--type=gpu-process" in cmd else "other"
        for tid in tids:
            try:
                stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
            except OSError:
                continue
            name = stat[stat.index("(") + 1:stat.rindex(")")]
            fields = stat.rsplit(")", 1)[1].split()
            group = ("renderer main" if kind == "renderer" and name.startswith("chrom") else
                     "GPU main" if kind == "gpu" and name.startswith("chrom") else
                     "GL raster" if kind == "gpu" and name.startswith("Thread<") else "other")  # SwiftShader's workers
            out[group] += (int(fields[11]) + int(fields[12])) / tick
    return out


def cpu_ms(pages: list[bytes]) -> list[dict[str, float]]:
    """Per page, the CPU ms a frame of Chromium's threads (CPU_COLUMNS) drawing the take in FINISH_LOOP, or []."""
    out = []
    for page in _paused_pages(pages):
        page.evaluate(FINISH_LOOP, 20)
        before = _chromium_cpu()
        page.evaluate(FINISH_LOOP, CPU_FRAMES)
        after = _chromium_cpu()
        out.append({g: 1000 * (after[g] - before[g]) / CPU_FRAMES for g in CPU_COLUMNS})
    return out


def _fps(got: dict) -> tuple[float, float, str]:
    """(rAF fps, frames drawn a second, renderer) from FPS_BODY's counts."""
    dt = max(float(got["dt"]), 1.0) / 1000.0
    playing = "" if got["playing"] else " (not playing)"
    return got["n"] / dt, got["drawn"] / dt, got["renderer"] + playing


def chromium_fps(pages: list[bytes]) -> dict[str, list[tuple[float, float, str]]]:
    """Per throttling (1x, THROTTLE x): each playing page's fps in headless Chromium; {} without it."""
    exe = chromium_path()
    if not exe:
        return {}
    out: dict[str, list[tuple[float, float, str]]] = {}
    with launched_chromium(exe) as browser, tempfile.TemporaryDirectory() as tmp:
        for rate in (1, THROTTLE):
            column = out.setdefault(f"Chromium {rate}x", [])
            for k, data in enumerate(pages):
                path = Path(tmp) / f"p{k}.html"
                path.write_bytes(data)
                page = browser.new_page(viewport={"width": 1024, "height": 800})
                page.context.new_cdp_session(page).send("Emulation.setCPUThrottlingRate", {"rate": rate})
                page.goto(path.as_uri())
                page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=300000)
                column.append(_fps(page.evaluate(FPS_PAGE, [WARM_S, PLAY_S])))
                page.close()
    return out


def engine_fps(pages: list[bytes]) -> tuple[dict[str, list[tuple[float, float, str]]], list[str]]:
    """Each playing page's fps in Firefox ESR and WebKitGTK (tests/engines.py), and notes on missing engines."""
    engines, notes = installed_engines()
    out: dict[str, list[tuple[float, float, str]]] = {}
    for name, launch in engines:
        with launch() as session:
            column = out.setdefault(name, [])
            for data in pages:
                session.load(data.decode("utf-8"))
                session.wait_for("document.documentElement.dataset.puppet", timeout=300)
                column.append(_fps(session.run_async(FPS_SESSION, WARM_S, PLAY_S)))
    return out, notes


def fps_table(labels: list[str], pages: list[bytes]) -> str:
    """Markdown: the playing puppet's fps per face and engine (issue 52's targets), or "" without any browser."""
    columns = chromium_fps(pages)
    more, notes = engine_fps(pages)
    columns.update(more)
    if not columns:
        return ""
    names = list(columns)
    rows = [f"| {label} | " + " | ".join(f"{columns[n][i][0]:.1f} / {columns[n][i][1]:.1f} ({columns[n][i][2]})"
                                        for n in names) + " |" for i, label in enumerate(labels)]
    return (f"\n\nPlayback (issue 52: >= 60 fps at {THROTTLE}x in Chromium, >= 50 fps in WebKitGTK and Firefox ESR): each face "
            f"with the Live Link Face take ({LLF.name}) embedded, playing on load; after {WARM_S:g} s of play, "
            f"requestAnimationFrame callbacks a second over {PLAY_S:g} s / frames the puppet drew a second "
            "(window.puppet.frames), and its renderer (window.puppet.renderer; headless Firefox has no WebGL, so "
            "the canvas 2D fallback). Chromium headless (SwiftShader), Firefox ESR headless, WebKitGTK's "
            "MiniBrowser on Xvfb; only Chromium is throttled (DevTools CPU throttling).\n\n"
            "| face | " + " | ".join(names) + " |\n|---|" + "---|" * len(names) + "\n" + "\n".join(rows)
            + "".join(f"\n\n{note}" for note in notes))


def measure(label: str, path: Path, takes: list[Path], played: list[bytes],
            live: list[bytes] | None = None) -> list[str]:
    """Table rows for one face: the puppet alone, then with each take embedded (the last one kept in played, the
    Live Link Face one in live)."""
    c0 = time.process_time()
    face = load_morph_face(path)
    load_s = time.process_time() - c0
    options = ConversionOptions(to="puppet")
    c0 = time.process_time()
    puppet = puppet_of(face, options)
    page = writer.write(puppet, options, Report())
    build_s = time.process_time() - c0
    zipped = len(gzip.compress(page, 9))
    info = puppet.info
    rows = [f"| {label} | {len(face.base):,} / {len(face.faces):,} | {info['vertices']:,} / {info['triangles']:,} | "
            f"{len(face.names)} ({info['morph_intervals']} intervals), {len(puppet.eyes)} eyes | {load_s:.2f} | "
            f"{build_s:.2f} | {len(page) / 1024:,.0f} | {zipped / 1024:,.0f} | - | - |"]
    for take_path in takes:
        c0 = time.process_time()
        take = from_track(read_weights(take_path))
        with_take = writer.replace_take(page, take)
        take_s = time.process_time() - c0
        extra = len(with_take) - len(page)
        extra_gz = len(gzip.compress(with_take, 9)) - zipped
        played.append(with_take) if take_path == takes[-1] else None
        if take_path == LLF and live is not None:
            live.append(with_take)
        rows.append(f"| ... + take of {take.n_frames:,} frames ({len(take.names)} weights) | | | | | {take_s:.2f} | "
                    f"+{extra / 1024:,.1f} | +{extra_gz / 1024:,.1f} | {take.bytes_per_frame} | "
                    f"{extra / take.n_frames:.1f} / {extra_gz / take.n_frames:.1f} |")
    return rows


def angle_limit(faces: list[tuple[str, Path]]) -> str:
    """Markdown: per face, head yaw and pitch 0-50 degrees, the (Gouraud) puppet in Chromium against our 3D
    prerender, silhouette IoU and luminance SSIM (tests/puppet/test_threejs.py measures the same), or "" without
    Chromium."""
    exe = chromium_path()
    if not exe:
        return ""
    rows = []
    with launched_chromium(exe) as browser:
        for label, path in faces:
            face = load_morph_face(path)
            puppet = puppet_of(face, ConversionOptions(size=SWEEP_SIZE, shading="gouraud"))
            page = writer.write(puppet, ConversionOptions(), Report())
            for axis, deg, iou, ssim, seen in threejs.angle_sweep(browser, face, page, puppet.camera, SWEEP):
                shown = (f"{iou:.4f} | {ssim:.4f}" if seen >= IN_VIEW else "out of view | out of view")
                rows.append(f"| {label} | {axis} | {deg:.0f} | {shown} | {seen:.2f} |")
    return (f"\n\nThe measured angle limit: head yaw, then pitch, the Gouraud puppet ({SWEEP_SIZE} px) in headless Chromium "
            "against our 3D prerender (converter/render.py), no morph weights; silhouette IoU and SSIM of the "
            "luminance over the union of the silhouettes; in view: the prerender's silhouette over its rest area (the "
            "head turns about the rest bounding box centre, a full-body avatar's chest):\n\n"
            "| face | axis | degrees | IoU | SSIM | in view |\n|---|---|---|---|---|---|\n" + "\n".join(rows))


def run() -> str:
    """The section's markdown."""
    head = ("| face | vertices / triangles | puppet vertices / triangles | parameters | load CPU s | build CPU s | "
            "package KB | gzip KB | take bytes/frame stored | take bytes/frame in the file (raw / gzip) |\n"
            "|---|---|---|---|---|---|---|---|---|---|")
    rows: list[str] = []
    played: list[bytes] = []
    live: list[bytes] = []
    labels = []
    with tempfile.TemporaryDirectory() as tmp:
        generated = Path(tmp) / "generated.zip"
        generated.write_bytes(face_zip())
        takes = []
        if LLF.exists():
            long = Path(tmp) / "long.csv"
            write_capture(long, LONG_FRAMES)
            takes = [LLF, long]
        faces = [("generated (tests/puppet/faces.py)", generated), ("ICT FaceKit head", ICT),
                 ("Ready Player Me avatar (rpm_template_xr.glb)", RPM)]
        for label, path in faces:
            if path.exists():
                rows += measure(label, path, takes or [LLF], played, live)
                labels.append(label)
        sweep = angle_limit([(label, path) for label, path in faces if path.exists()])
    note = "" if ICT.exists() else "\n\n../shared/data is missing: only the generated face was measured."
    timing = draw_ms(played) if takes else []
    if timing:
        note += ("\n\nPlaying the 4,000-frame take in headless Chromium (software GL: SwiftShader), the script's time to "
                 f"evaluate and draw a frame (mean of {DRAWS}), unthrottled and at {THROTTLE}x CPU throttling:\n\n"
                 "| face | renderer | ms a frame | ms at 4x |\n|---|---|---|---|\n" +
                 "\n".join(f"| {label} | {r} | {a:.1f} | {b:.1f} |" for label, (a, b, r) in zip(labels, timing)))
    cpu = cpu_ms(played) if takes else []
    if cpu:
        note += (f"\n\nThe same in CPU: Chromium's threads' CPU ms a frame (from /proc) over {CPU_FRAMES} frames of the take, "
                 "each drawn and finished (gl.finish) before the next, unthrottled: the renderer's main thread (the "
                 "script), the GPU process's main thread, its SwiftShader workers (GL raster) and the rest (one "
                 "load average's noise is in these, less than in fps):\n\n"
                 "| face | " + " | ".join(CPU_COLUMNS) + " | total |\n|---|" + "---|" * (len(CPU_COLUMNS) + 1) + "\n" +
                 "\n".join(f"| {label} | " + " | ".join(f"{row[g]:.2f}" for g in CPU_COLUMNS) +
                           f" | {sum(row.values()):.2f} |" for label, row in zip(labels, cpu)))
    fps = fps_table(labels, live) if live else ""
    return head + "\n" + "\n".join(rows) + note + fps + sweep
