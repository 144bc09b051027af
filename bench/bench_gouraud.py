"""Gouraud-shaded SVG (issue 4): exact one-gradient method vs the chapter's three-gradient filter method."""

from __future__ import annotations

import io
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TITLE = "Gouraud-shaded SVG (issue 4)"
ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"
SIZE = 512
REPEATS = 3
FRAME_FRACTION = 0.5  # the still is taken half-way through the animation (expression and rotation under way)
CHAPTER_ROW = ("chapter's Table 12.5 'Gouraud'", 484, 610 * 1024, 3.0)

sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def ict_face_fallback(triangles: int = 5000, n_frames: int = 24):
    """A ~5,000-triangle ICT face (smile, jaw open, a little yaw), used until bench/faces.py exists."""
    from converter.animation import FaceAnimation, Part
    from converter.formats.ictfacekit import PART_ORDER, load_ict_head
    from samples.ict_region import face_region

    head = load_ict_head(ROOT.parent / "shared" / "data" / "ict_facekit")
    pieces = face_region(head, triangles)
    ids = np.concatenate([p.ids for p in pieces])
    offsets = np.cumsum([0] + [len(p.ids) for p in pieces])
    faces = np.concatenate([p.faces + o for p, o in zip(pieces, offsets[:-1])])
    part_names = sorted({p.part for p in pieces}, key=PART_ORDER.index)
    pid = np.concatenate([np.full(len(p.faces), part_names.index(p.part)) for p in pieces])
    parts = tuple(next(hp for hp in head.parts if hp.name == n) for n in part_names)
    smile = sum(head.delta(n) for n in ("mouthSmile_L", "mouthSmile_R"))[ids]
    jaw = head.delta("jawOpen")[ids]
    base = head.vertices[ids]
    frames = []
    for k in range(n_frames):
        s = k / max(n_frames - 1, 1)
        a = np.radians(25 * s)
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        frames.append(((base + s * smile + 0.5 * s * jaw) @ r.T).astype(np.float32))
    return FaceAnimation(np.stack(frames), faces, pid, tuple(Part(p.name, p.color) for p in parts), 24.0, "ict-bench")


def bench_faces() -> list[tuple[str, object]]:
    """(label, FaceAnimation) for the bundled sample and the 5,000-triangle ICT face."""
    from converter import formats

    out = []
    sample = ROOT / "samples" / "face.glb"
    if sample.exists():
        out.append(("sample (samples/face.glb)", formats.load(sample)))
    try:
        sys.path.insert(0, str(ROOT / "bench"))
        from faces import ict_bench_face

        out.append(("ICT 5k face (bench/faces.py)", ict_bench_face()))
    except ImportError:
        out.append(("ICT 5k face (fallback builder)", ict_face_fallback()))
    return out


def over_black(rgba: np.ndarray) -> np.ndarray:
    """RGB float of an RGBA image composited over black."""
    return rgba[..., :3].astype(np.float64) * (rgba[..., 3:4] / 255.0)


def scores(img: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(SSIM, PSNR dB) of two RGBA images composited over black."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    a, b = over_black(img), over_black(ref)
    return (float(structural_similarity(a, b, channel_axis=2, data_range=255)),
            float(peak_signal_noise_ratio(b, a, data_range=255)))


def firefox_frame(svg: bytes, size: int) -> np.ndarray | None:
    """Firefox's headless screenshot of the SVG over black, or None when Firefox is not installed."""
    from PIL import Image

    exe = shutil.which("firefox-esr") or shutil.which("firefox")
    if not exe:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "page.html"
        page.write_bytes(b"<!doctype html><html><body style='margin:0;background:#000'>" + svg + b"</body></html>")
        shot = Path(tmp) / "shot.png"
        env = dict(os.environ, HOME=tmp, MOZ_HEADLESS="1")
        subprocess.run([exe, "--headless", "--no-remote", "--profile", tmp, "--window-size", f"{size},{size}",
                        "--screenshot", str(shot), page.as_uri()], env=env, capture_output=True, timeout=120)
        if not shot.exists():
            return None
        img = np.asarray(Image.open(shot).convert("RGBA"))[:size, :size].copy()
    img[..., 3] = 255
    return img


def resvg_frame(svg: bytes, zoom: float = 1.0) -> np.ndarray:
    """resvg-py raster (RGBA) of the SVG."""
    import resvg_py
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(bytes(resvg_py.svg_to_bytes(svg_string=svg.decode(), zoom=zoom))))
                      .convert("RGBA"))


def timed_write(sheet, options, repeats: int = REPEATS) -> tuple[bytes, float, object]:
    """(SVG bytes, median seconds over repeats, Report) of one writer call."""
    from converter.options import Report
    from converter.outputs import writer_for

    write = writer_for(options)
    times, data, report = [], b"", None
    for _ in range(repeats):
        report = Report()
        t = time.perf_counter()
        data = write(sheet, options, report)
        times.append(time.perf_counter() - t)
    return data, statistics.median(times), report


def renders(browser, svg: bytes, ref: np.ndarray, label: str) -> dict[str, object]:
    """SSIM/PSNR in Chromium, resvg and Firefox, and crack pixels (Chromium, 1x and 2x)."""
    from PIL import Image

    from svgrender import chromium_frame

    out: dict[str, object] = {}
    t = time.perf_counter()
    chrome = chromium_frame(browser, svg, 0.0, SIZE, SIZE)
    out["chrome_s"] = time.perf_counter() - t
    Image.fromarray(chrome).save(OUT / f"gouraud_{label}_chromium.png")
    out["chrome"] = scores(chrome, ref)
    out["resvg"] = scores(resvg_frame(svg), ref)
    ff = firefox_frame(svg, SIZE)
    if ff is not None:
        Image.fromarray(ff).save(OUT / f"gouraud_{label}_firefox.png")
        out["firefox"] = scores(ff, np.dstack([over_black(ref).round().astype(np.uint8), np.full(ref.shape[:2], 255, np.uint8)]))
    for zoom in (1, 2):
        img = chrome if zoom == 1 else chromium_frame(browser, svg, 0.0, SIZE, SIZE, scale=zoom)
        out[f"cracks{zoom}"] = [crack_pixels(img, ref[..., 3], zoom, lim) for lim in (250, 230)]
    return out


def crack_pixels(img: np.ndarray, ref_alpha: np.ndarray, zoom: int, limit: int = 250) -> tuple[int, int]:
    """(pixels inside the prerender's silhouette eroded 2 px whose alpha is below limit, interior pixels)."""
    from scipy import ndimage

    inside = ndimage.binary_erosion(ref_alpha > 0, iterations=2)
    if zoom != 1:
        inside = np.kron(inside, np.ones((zoom, zoom), bool))
    return int(((img[..., 3] < limit) & inside).sum()), int(inside.sum())


def variants(sheet, k: int):
    """(label, options, patch) rows: flat for reference, the chapter (sRGB and default linearRGB filters), exact."""
    from converter.options import ConversionOptions

    def linear_filters(data: bytes) -> bytes:
        return data.replace(b' color-interpolation-filters="sRGB"', b"")

    yield "flat (svg_anim, reference)", ConversionOptions(shading="flat", frame=k), None
    yield "chapter: 3 ramps + feComposite + feColorMatrix", ConversionOptions(shading="gouraud-chapter", frame=k), None
    yield "chapter, filters left in linearRGB", ConversionOptions(shading="gouraud-chapter", frame=k), linear_filters
    yield "exact: 1 gradient, 1 px interior stroke, underlay", ConversionOptions(shading="gouraud", frame=k), None
    yield "exact, no underlay", ConversionOptions(shading="gouraud", frame=k), {"UNDERLAY": False}
    yield "exact, no underlay, no stroke", ConversionOptions(shading="gouraud", frame=k), {
        "UNDERLAY": False, "SEAM_STROKE": 0}
    yield "exact, no underlay, 1 px stroke on every edge", ConversionOptions(shading="gouraud", frame=k), {
        "UNDERLAY": False, "outline_edges": lambda t, ids=None: np.zeros(np.shape(t), bool)}
    yield "exact, no underlay, 1.5 px interior stroke", ConversionOptions(shading="gouraud", frame=k), {
        "UNDERLAY": False, "SEAM_STROKE": 1.5}


def write_variant(sheet, options, patch):
    """Write one variant, applying its patch (a post-edit of the bytes or writer constants) for the call."""
    from converter.writers import svg_gouraud

    if patch is None or callable(patch):
        data, secs, report = timed_write(sheet, options)
        return (patch(data) if patch else data), secs, report
    saved = {name: getattr(svg_gouraud, name) for name in patch}
    try:
        for name, value in patch.items():
            setattr(svg_gouraud, name, value)
        return timed_write(sheet, options)
    finally:
        for name, value in saved.items():
            setattr(svg_gouraud, name, value)


def fmt_scores(s) -> str:
    return f"{s[0]:.4f} / {s[1]:.1f}" if s else "n/a"


def run() -> str:
    """Markdown: per face and method, SSIM/PSNR per renderer, bytes, generation time, cracks; the chapter row."""
    from playwright.sync_api import sync_playwright

    from conftest import CHROMIUM_ARGS, chromium_path
    from converter.extract import extract, fit_camera
    from converter.options import ConversionOptions
    from svgrender import chromium_frame

    OUT.mkdir(parents=True, exist_ok=True)
    has_ff = bool(shutil.which("firefox-esr") or shutil.which("firefox"))
    sections = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            for label, anim in bench_faces():
                k = int(anim.n_frames * FRAME_FRACTION)
                sheet = extract(anim, fit_camera(anim, SIZE), reference_frames=(k,))
                ref = sheet.references[k]
                n_vis = int(sheet.visible[k, sheet.order].sum())
                rows, sizes = [], {}
                for name, options, patch in variants(sheet, k):
                    data, secs, _ = write_variant(sheet, options, patch)
                    tag = f"{label.split()[0]}_{len(rows)}"
                    (OUT / f"gouraud_{tag}.svg").write_bytes(data)
                    r = renders(browser, data, ref, tag)
                    sizes[name] = len(data)
                    c1, c2 = r["cracks1"], r["cracks2"]
                    rows.append(
                        f"| {name} | {fmt_scores(r['chrome'])} | {fmt_scores(r['resvg'])} | "
                        f"{fmt_scores(r.get('firefox')) if has_ff else 'not installed'} | {len(data):,} | {secs:.2f} | "
                        f"{r['chrome_s']:.1f} | {c1[0][0]:,} / {c1[1][0]:,} | {c2[0][0]:,} / {c2[1][0]:,} |"
                    )
                anim_rows = []
                for shading, raw in (("gouraud", False), ("gouraud", True), ("gouraud-chapter", False)):
                    data, secs, rep = timed_write(sheet, ConversionOptions(shading=shading, raw=raw), 1)
                    keys = rep.counts.get("gouraud_keys", (anim.n_frames + 1) * len(sheet.order))
                    at_k = ""
                    if shading == "gouraud" and not raw:
                        img = chromium_frame(browser, data, k / anim.fps, SIZE, SIZE)
                        cr = crack_pixels(img, ref[..., 3], 1, 250)[0], crack_pixels(img, ref[..., 3], 1, 230)[0]
                        at_k = f"{fmt_scores(scores(img, ref))}, cracks {cr[0]:,} / {cr[1]:,}"
                    anim_rows.append(f"| {shading}{' --raw' if raw else ''} | {len(data):,} | {secs:.2f} | {keys:,} | "
                                     f"{at_k or 'not rendered'} |")
                    del data
                ratio = sizes["exact: 1 gradient, 1 px interior stroke, underlay"] / sizes[
                    "chapter: 3 ramps + feComposite + feColorMatrix"]
                interior = crack_pixels(ref, ref[..., 3], 1)[1]
                sections.append(
                    f"### {label}: {anim.n_faces:,} triangles, {len(sheet.order):,} kept, {n_vis:,} drawn in frame {k} "
                    f"of {anim.n_frames}, {SIZE} px\n\n"
                    "| method | Chromium SSIM / PSNR dB | resvg SSIM / PSNR | Firefox SSIM / PSNR | bytes | write s | "
                    "Chromium raster s | cracks 1x (alpha<250 / <230) | cracks 2x |\n|---|---|---|---|---|---|---|---|---|\n"
                    + "\n".join(rows)
                    + f"\n| {CHAPTER_ROW[0]} | n/a | n/a | n/a | {CHAPTER_ROW[2]:,} ({CHAPTER_ROW[1]} polys) | "
                    f"{CHAPTER_ROW[3]:.0f} | n/a | n/a | n/a |\n\n"
                    f"Exact file / chapter file = {ratio:.1%} (target <= 40%). Interior pixels: {interior:,} at 1x "
                    f"({4 * interior:,} at 2x).\n\n"
                    "Animated Gouraud SVG of the whole sequence (gradient endpoints and stop colours animated; "
                    "keyframes from converter.encode.keys at tolerance 0.25 px / 2 colour levels unless --raw; one timed run each):\n\n"
                    f"| output | bytes | write s | keys | Chromium at t = {k}/fps: SSIM / PSNR, cracks |\n"
                    "|---|---|---|---|---|\n" + "\n".join(anim_rows)
                )
        finally:
            browser.close()
    return (
        "Stills of one frame written by each method and rasterised by headless Chromium (Playwright, Debian "
        "chromium), resvg-py and Firefox ESR (headless --screenshot, over black), compared with the pyrender "
        "prerender of the same camera and lights (`render_frames`: GL-interpolated lit vertex colours). SSIM "
        "(skimage, RGB over black, data range 255) and PSNR over the whole 512 px image. Write times are medians "
        f"of {REPEATS} calls of the writer on an extracted Sheet (extraction excluded). Cracks: pixels inside the "
        "prerender's silhouette (eroded 2 px) that the SVG leaves partly transparent, i.e. where the background "
        "would leak through seams, at device scale 1 and 2. A renderer draws a method correctly when its SSIM "
        "matches Chromium's within 0.01 (a renderer without feImage-of-element support drops the chapter method "
        "to the flat score or below).\n\n" + "\n\n".join(sections)
    )
