"""`--to puppet`: building a face's 2D puppet, its package size and what a take costs a frame.

Faces: the tests' generated face (tests/puppet/faces.py), and where ../shared/data exists the ICT FaceKit head and
the Ready Player Me avatar, each with the real Live Link Face take (livelinkface_MySlate_3.csv) embedded and a
4,000-frame take of the same 61 columns. Build CPU is the puppet stage and the writer (loading the face and the
capture is the loaders' cost, shown apart); the package is the HTML without a take, raw and gzipped.
"""

from __future__ import annotations

import gzip
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_weights import write_capture
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


def draw_ms(pages: list[bytes]) -> list[tuple[float, float, str]]:
    """(ms a frame unthrottled, at THROTTLE x, renderer) of each page in headless Chromium, or [] without it."""
    exe = chromium_path()
    if not exe:
        return []
    out = []
    with launched_chromium(exe) as browser, tempfile.TemporaryDirectory() as tmp:
        for k, data in enumerate(pages):
            path = Path(tmp) / f"p{k}.html"
            path.write_bytes(data)
            page = browser.new_page(viewport={"width": 1024, "height": 800})
            page.goto(path.as_uri() + "?paused")
            page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=120000)
            page.evaluate("() => puppet.pause()")
            plain = page.evaluate(DRAW_LOOP, DRAWS)
            cdp = page.context.new_cdp_session(page)
            cdp.send("Emulation.setCPUThrottlingRate", {"rate": THROTTLE})
            slow = page.evaluate(DRAW_LOOP, DRAWS)
            out.append((plain, slow, page.evaluate("() => puppet.renderer")))
            page.close()
    return out


def measure(label: str, path: Path, takes: list[Path], played: list[bytes]) -> list[str]:
    """Table rows for one face: the puppet alone, then with each take embedded (the last one kept in played)."""
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
                rows += measure(label, path, takes or [LLF], played)
                labels.append(label)
        sweep = angle_limit([(label, path) for label, path in faces if path.exists()])
    note = "" if ICT.exists() else "\n\n../shared/data is missing: only the generated face was measured."
    timing = draw_ms(played) if takes else []
    if timing:
        note += ("\n\nPlaying the 4,000-frame take in headless Chromium (software GL: SwiftShader), the script's time to "
                 f"evaluate and draw a frame (mean of {DRAWS}), unthrottled and at {THROTTLE}x CPU throttling:\n\n"
                 "| face | renderer | ms a frame | ms at 4x |\n|---|---|---|---|\n" +
                 "\n".join(f"| {label} | {r} | {a:.1f} | {b:.1f} |" for label, (a, b, r) in zip(labels, timing)))
    return head + "\n" + "\n".join(rows) + note + sweep
