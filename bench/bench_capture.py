"""Captured motion (issue 9): rigid factoring, the other size levers, the default tolerance by measurement.

Face: bench/capture_like.py (ICT head, ~8,000 triangles, 335 frames at 30 fps, head sway and turns, eye
rotations, capture jitter). Everything is generated in memory; SVGs for inspection go to bench/out/.
"""

from __future__ import annotations

import gzip
import io
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.capture_like import capture_like, motion_stats
from converter import extract, smoothing
from converter.encode import freeknots
from converter.encode import keys as keyframes
from converter.encode.budget import viewbox_scale
from converter.options import ConversionOptions, Report
from converter.verify import verify_animation
from converter.writers import svg_anim

TITLE = "Captured motion: rigid factoring, size levers, default tolerance (issue 9)"
OUT = ROOT / "bench" / "out"
TOLERANCES = (0.1, 0.25, 0.5, 1.0)
VISUAL_TOLERANCES = (0.1, 0.25, 0.5, 0.75, 1.0, 1.5)
VISUAL_FRAMES = (10, 35, 60, 85)  # rendered frames (inside the first 90, the subset the page loads)
VISUAL_END = 90
SSIM_INVISIBLE = 0.99  # mean SSIM at or above this, and ...
P999_INVISIBLE = 32  # ... 99.9th percentile of per-pixel max channel difference at or below this (8-bit)
SMOOTH_SIGMAS = (0.5, 1.0, 2.0)


def _kb(n: float) -> str:
    return f"{n / 1024:,.0f}"


def _pct(n: float, raw: float) -> str:
    return f"{100 * n / raw:.1f}%"


def _gz(data: bytes) -> int:
    return len(gzip.compress(data, 9, mtime=0))


def _write(sheet, options: ConversionOptions, repeats: int = 1) -> tuple[bytes, Report, float]:
    """The SVG writer on an extracted sheet: bytes, report and median seconds."""
    times, data, report = [], b"", Report()
    for _ in range(repeats):
        report = Report()
        t = time.perf_counter()
        data = svg_anim.write(sheet, options, report)
        times.append(time.perf_counter() - t)
    return data, report, statistics.median(times)


def _sheet(anim, size: int):
    return extract.extract(anim, extract.fit_camera(anim, size))


# --- the levers measured on their own, by rewriting the paths of one output -----------------------------------
_D = re.compile(r'( d="|values=")([^"]*)"')
_PATH = re.compile(r"m(-?\d+) ?(-?\d+) ?(-?\d+) ?(-?\d+) ?(-?\d+) ?(-?\d+)z")


def _rewrite_paths(data: bytes, fn) -> bytes:
    """Apply fn to every relative integer triangle 'Mx yl..z' in d attributes and d values."""
    text = data.decode()

    def one(m: re.Match) -> str:
        x, y, a, b, c, d = (int(v) for v in m.groups())
        return fn(x, y, a, b, c, d)

    return _PATH.sub(one, text).encode()


def _absolute(x, y, a, b, c, d) -> str:
    return f"M{x} {y}L{x + a} {y + b} {x + a + c} {y + b + d}z".replace(" -", "-")


def _decimals_px(scale: int):
    def fn(x, y, a, b, c, d) -> str:
        pts = np.array([x, y, x + a, y + b, x + a + c, y + b + d]) / scale
        s = [f"{v:.2f}".rstrip("0").rstrip(".") for v in pts]
        return f"M{s[0]} {s[1]}L{s[2]} {s[3]} {s[4]} {s[5]}z".replace(" -", "-")

    return fn


def _keytimes_bytes(data: bytes) -> tuple[int, int, int]:
    """Bytes of keyTimes attributes, how many there are, and how many repeat an earlier one exactly."""
    kts = re.findall(rb'keyTimes="([^"]*)"', data)
    return sum(len(k) + 12 for k in kts), len(kts), len(kts) - len(set(kts))


# --- visual: Chromium renders at several tolerances against the exact frame ------------------------------------
def _frames_in_chromium(browser, svg: bytes, times: list[float], size: int) -> list[np.ndarray]:
    """RGB float (H, W, 3) over white of the SVG paused at each time, loading the page once."""
    from PIL import Image

    page = browser.new_page(viewport={"width": size, "height": size})
    out = []
    try:
        page.set_content("<!doctype html><html><body style='margin:0'>" + svg.decode() + "</body></html>")
        for t in times:
            page.evaluate("(t) => { const s = document.querySelector('svg'); s.pauseAnimations(); s.setCurrentTime(t); }", t)
            page.wait_for_timeout(50)
            png = page.locator("svg").screenshot(animations="allow")
            out.append(np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.float64))
    finally:
        page.close()
    return out


def _visual(anim, size: int) -> list[dict]:
    """SSIM and pixel differences of the animated SVG (paused at frame k) against an exact still of frame k."""
    from playwright.sync_api import sync_playwright
    from skimage.metrics import structural_similarity

    from tests.conftest import CHROMIUM_ARGS, chromium_path

    sub = anim.sliced(0, VISUAL_END)
    sheet = _sheet(sub, size)
    exact_opts = ConversionOptions(size=size, tolerance=0.01)  # 1/283 px grid: exact for display
    times = [k / sheet.fps for k in VISUAL_FRAMES]
    rows = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            refs = [_frames_in_chromium(browser, svg_anim.write_still(sheet, exact_opts, Report(), k), [0.0], size)[0]
                    for k in VISUAL_FRAMES]
            for tol in VISUAL_TOLERANCES:
                for rigid in (True, False):
                    data, _, _ = _write(sheet, ConversionOptions(size=size, tolerance=tol, rigid=rigid))
                    imgs = _frames_in_chromium(browser, data, times, size)
                    ssim = [structural_similarity(i, r, channel_axis=2, data_range=255) for i, r in zip(imgs, refs)]
                    diff = [np.abs(i - r).max(axis=2) for i, r in zip(imgs, refs)]
                    rows.append({"tol": tol, "rigid": rigid, "ssim_mean": float(np.mean(ssim)),
                                 "ssim_min": float(np.min(ssim)),
                                 "p999": float(max(np.percentile(d, 99.9) for d in diff)),
                                 "max": float(max(d.max() for d in diff)), "kb": len(data) / 1024})
        finally:
            browser.close()
    return rows


def run() -> str:
    OUT.mkdir(parents=True, exist_ok=True)
    anim = capture_like()
    stats = motion_stats(anim)
    t = time.perf_counter()
    sheet = _sheet(anim, 512)
    extract_s = time.perf_counter() - t
    raw = svg_anim.encode(sheet, ConversionOptions(), Report(), "raw")
    raw_n, raw_gz = len(raw), _gz(raw)
    del raw
    lines = [
        f"Face: `bench/capture_like.py` — ICT head region, {anim.n_faces} triangles ({len(sheet.order)} ever seen), "
        f"{anim.n_frames} frames at {anim.fps:g} fps, 512 px; head turns up to +-20 deg, sway, eye saccades, "
        f"capture jitter. Median vertex motion {stats['median_px_per_frame']:.2f} px/frame "
        f"(90th percentile {stats['p90_px_per_frame']:.2f}). Extraction {extract_s:.1f} s. "
        f"Raw = every frame, 2 decimals: {_kb(raw_n)} KB ({_kb(raw_gz)} KB gzipped).",
        "",
        "Size against tolerance. `plain` = the error-bounded encoder alone (`--no-rigid`); `rigid` = rigid factoring"
        " (default). Max px: `verify` (SMIL, group transforms included, every frame, every drawn vertex). Write s:"
        " the writer on the extracted sheet (median of 3 at 0.25 and 0.5 px, else 1 run); triangle-frames/s ="
        " drawn paths x frames / write s.",
        "",
        "| tolerance px | plain KB (% raw) | keys/path plain | rigid KB (% raw) | gzip KB (% raw) | keys/path rigid |"
        " groups (runs, bands) | transform KB | verified max px | write s plain / rigid | triangle-frames/s rigid |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    kept: dict[float, bytes] = {}
    for tol in TOLERANCES:
        reps = 3 if tol in (0.25, 0.5) else 1
        plain, rp, sp = _write(sheet, ConversionOptions(tolerance=tol, rigid=False), reps)
        data, rr, sr = _write(sheet, ConversionOptions(tolerance=tol), reps)
        v = verify_animation(data, anim)
        kept[tol] = data
        st = {k: rr.counts.get(f"rigid_{k}", 0) for k in ("groups", "runs", "bands", "transform_bytes")}
        tf = rr.counts["paths"] * anim.n_frames / sr
        _SPEED[tol] = (tf, rp.counts["paths"] * anim.n_frames / sp)
        lines.append(
            f"| {tol:g} | {_kb(len(plain))} ({_pct(len(plain), raw_n)}) | {rp.figures['keys_per_path']:.1f} | "
            f"{_kb(len(data))} ({_pct(len(data), raw_n)}) | {_kb(_gz(data))} ({_pct(_gz(data), raw_n)}) | "
            f"{rr.figures['keys_per_path']:.1f} | {st['groups']} ({st['runs']}, {st['bands']}) | "
            f"{_kb(st['transform_bytes'])} | {v.max_px:.3f}{'' if v.ok else ' FAIL'} | {sp:.2f} / {sr:.2f} | "
            f"{tf / 1e6:.2f} M |")
        (OUT / f"capture_{tol:g}.svg").write_bytes(data)
    lines += ["", *_levers(sheet, anim, kept[0.5], raw_n), "", *_mobile(anim), ""]
    visual = _visual(anim, 512)
    lines += _visual_table(visual)
    lines += ["", *_targets(raw_n, kept, visual)]
    return "\n".join(lines)


def _levers(sheet, anim, data: bytes, raw_n: int) -> list[str]:
    """Each lever on its own at 0.5 px, against the default output."""
    scale = viewbox_scale(0.5)
    base = len(data)
    absolute = len(_rewrite_paths(data, _absolute))
    decimals = len(_rewrite_paths(data, _decimals_px(scale)))
    kt_bytes, kt_n, kt_dup = _keytimes_bytes(data)
    with_l = len(_rewrite_paths(data, lambda x, y, a, b, c, d: f"M{x} {y}l{a} {b} {c} {d}z".replace(" -", "-")))
    real_offsets = svg_anim.offsets
    svg_anim.offsets = lambda rows, pk, p: np.zeros((p, 2), np.int64)
    try:
        no_offsets, _, _ = _write(sheet, ConversionOptions(tolerance=0.5))
    finally:
        svg_anim.offsets = real_offsets
    sampled = _without_free_knots(sheet)
    real_shapes = freeknots.SHAPES_DEG
    freeknots.SHAPES_DEG = real_shapes[:1]
    try:
        squares, _, _ = _write(sheet, ConversionOptions(tolerance=0.5))
    finally:
        freeknots.SHAPES_DEG = real_shapes
    out = [
        "Levers, each on its own, at 0.5 px (default output = rigid, relative integer paths; sizes in KB; %"
        " of raw):",
        "",
        "| lever | without | with | saves |",
        "|---|---|---|---|",
        f"| relative path coordinates (vs absolute `M x y L x y x y z`) | {_kb(absolute)} | {_kb(base)} |"
        f" {_pct(absolute - base, raw_n)} of raw |",
        f"| precision tied to tolerance (integers on a 1/{scale} px grid vs 2-decimal px) | {_kb(decimals)} |"
        f" {_kb(base)} | {_pct(decimals - base, raw_n)} of raw |",
        f"| implicit linetos (`m x y dx dy dx dy z` vs `M x y l dx dy dx dy z`) | {_kb(with_l)} | {_kb(base)} |"
        f" {_pct(with_l - base, raw_n)} of raw |",
        f"| a static per-path `translate` where it shortens the keys' moveto numbers | {_kb(len(no_offsets))} |"
        f" {_kb(base)} | {_pct(len(no_offsets) - base, raw_n)} of raw |",
        f"| keyTimes: {kt_n} attributes, {kt_dup} repeat an earlier one verbatim (the most sharing could save) |"
        f" {_kb(base)} | {_kb(base - kt_bytes * kt_dup / max(kt_n, 1))} | at most {_pct(kt_bytes * kt_dup / max(kt_n, 1), raw_n)}"
        f" of raw ({_kb(kt_bytes)} KB of keyTimes in all) |",
        f"| free-knot keys (`converter/encode/freeknots.py`) vs keys on sampled values, same per-axis bound |"
        f" {_kb(len(sampled))} (gzip {_kb(_gz(sampled))}) | {_kb(base)} (gzip {_kb(_gz(data))}) |"
        f" {_pct(len(sampled) - base, raw_n)} of raw, gzip {_pct(_gz(sampled) - _gz(data), raw_n)} |",
        f"| per path the rectangle ({', '.join(f'{a:g}' for a in real_shapes)} deg) in the tolerance circle needing"
        f" fewest keys (a rectangle tried where the path's jitter leans its way) vs the square only"
        f" | {_kb(len(squares))} (gzip {_kb(_gz(squares))}) | {_kb(base)} |"
        f" {_pct(len(squares) - base, raw_n)} of raw, gzip {_pct(_gz(squares) - _gz(data), raw_n)} |",
        f"| gzip -9 | {_kb(base)} | {_kb(_gz(data))} | {_pct(base - _gz(data), raw_n)} of raw |",
    ]
    for sigma in SMOOTH_SIGMAS:
        rep = Report()
        sm = smoothing.apply(anim, ConversionOptions(smooth=sigma), rep)
        sh = _sheet(sm, 512)
        d, _, _ = _write(sh, ConversionOptions(tolerance=0.5, smooth=sigma))
        _SMOOTH[sigma] = (len(d), _gz(d), rep.figures["smooth_max_px"])
        out.append(f"| `--smooth {sigma:g}` (deviation from the unsmoothed input: max "
                   f"{rep.figures['smooth_max_px']:.2f} px, mean {rep.figures['smooth_mean_px']:.3f} px) |"
                   f" {_kb(base)} | {_kb(len(d))} ({_pct(len(d), raw_n)}; gzip {_pct(_gz(d), raw_n)}) |"
                   f" {_pct(base - len(d), raw_n)} of raw |")
    return out


def _sampled_block(x, active, eps, limit, scale=None):
    """freeknots._reduce_block's contract with keys on sampled values (keyframes.reduce); never gives up."""
    xs = np.asarray(x if scale is None else x * scale, np.float64)
    k = keyframes.reduce(xs, active, eps)
    values = k.values if scale is None else k.values / scale
    return keyframes.Keys(k.mask, values, np.zeros(0, np.int64)), np.zeros(x.shape[1], bool)


def _without_free_knots(sheet) -> bytes:
    """The default output at 0.5 px with every path key on a sampled value (keyframes.reduce): the
    free-knot kernel (freeknots._reduce_block, which point_keys and reduce_free call) swapped out."""
    real = freeknots._reduce_block
    freeknots._reduce_block = _sampled_block
    try:
        return _write(sheet, ConversionOptions(tolerance=0.5))[0]
    finally:
        freeknots._reduce_block = real


def _mobile(anim) -> list[str]:
    """The mobile preset: --max-triangles 1500 --size 256, through prepare (simplify) and the writer."""
    from converter.convert import prepare

    rep = Report()
    small = prepare(anim, ConversionOptions(max_triangles=1500, size=256), rep)
    sheet = _sheet(small, 256)
    raw = svg_anim.encode(sheet, ConversionOptions(size=256), Report(), "raw")
    out = [f"Mobile preset `--max-triangles 1500 --size 256`: {small.n_faces} triangles ({len(sheet.order)} ever seen),"
           f" raw {_kb(len(raw))} KB; budget deviation max {rep.figures.get('budget_deviation_px', float('nan')):.1f} px.",
           "", "| tolerance px | plain KB | rigid KB (% raw) | gzip KB | verified max px | write s |", "|---|---|---|---|---|---|"]
    for tol in (0.25, 0.5, 1.0):
        plain, _, _ = _write(sheet, ConversionOptions(size=256, tolerance=tol, rigid=False))
        data, _, s = _write(sheet, ConversionOptions(size=256, tolerance=tol))
        v = verify_animation(data, small)
        out.append(f"| {tol:g} | {_kb(len(plain))} | {_kb(len(data))} ({_pct(len(data), len(raw))}) | {_kb(_gz(data))} |"
                   f" {v.max_px:.3f} | {s:.2f} |")
        _MOBILE[tol] = (len(data), _gz(data))
    for sigma in (1.0, 2.0):
        rep = Report()
        sm = prepare(anim, ConversionOptions(max_triangles=1500, size=256, smooth=sigma), rep)
        sh = _sheet(sm, 256)
        for tol in (0.25, 0.5):
            data, _, s = _write(sh, ConversionOptions(size=256, tolerance=tol, smooth=sigma))
            v = verify_animation(data, sm)
            out.append(f"| {tol:g} + `--smooth {sigma:g}` (max {rep.figures['smooth_max_px']:.2f} px, mean "
                       f"{rep.figures['smooth_mean_px']:.3f} px from the unsmoothed input) | | {_kb(len(data))} "
                       f"({_pct(len(data), len(raw))}) | {_kb(_gz(data))} | {v.max_px:.3f} | {s:.2f} |")
            _MOBILE[(tol, sigma)] = (len(data), _gz(data))
    return out


_MOBILE: dict = {}  # tolerance or (tolerance, smooth sigma) -> (SVG bytes, gzip bytes)
_SMOOTH: dict[float, tuple[int, int, float]] = {}  # sigma -> (SVG bytes, gzip bytes, max deviation px) at 0.5 px
_SPEED: dict[float, tuple[float, float]] = {}  # tolerance -> triangle-frames/s of the writer (rigid, plain)


def _visual_table(rows: list[dict]) -> list[str]:
    out = [f"Default tolerance by measurement: Chromium renders the animated SVG paused at frames "
           f"{', '.join(map(str, VISUAL_FRAMES))} (frame-range subset 0..{VISUAL_END - 1} so the page stays small)"
           " and the exact still of the same frame (1/283 px grid, exact colours), over white; SSIM (scikit-image,"
           " RGB) and per-pixel max channel difference (8-bit). Invisible = mean SSIM >= "
           f"{SSIM_INVISIBLE} and 99.9th-percentile difference <= {P999_INVISIBLE}.",
           "", "| tolerance px | encoding | KB (90 frames) | SSIM mean (min) | 99.9% diff | max diff | invisible |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['tol']:g} | {'rigid' if r['rigid'] else 'plain'} | {r['kb']:,.0f} | {r['ssim_mean']:.4f} "
                   f"({r['ssim_min']:.4f}) | {r['p999']:.0f} | {r['max']:.0f} | {'yes' if _invisible(r) else 'no'} |")
    best = max((r["tol"] for r in rows if r["rigid"] and _invisible(r)), default=None)
    out += ["", f"Largest invisible tolerance (rigid): {best if best is not None else 'none'} px."]
    return out


def _invisible(r: dict) -> bool:
    return r["ssim_mean"] >= SSIM_INVISIBLE and r["p999"] <= P999_INVISIBLE


def _targets(raw_n: int, kept: dict[float, bytes], visual: list[dict]) -> list[str]:
    def mark(ok: bool) -> str:
        return "met" if ok else "missed"

    s05, s025 = len(kept[0.5]), len(kept[0.25])
    g05 = _gz(kept[0.5])
    m_raw, m_gz = _MOBILE.get(0.25, (0, 0))
    return [
        "Targets (issue 9) side by side:", "",
        "| target | measured | |", "|---|---|---|",
        f"| <= 12% of raw at 0.5 px | {_pct(s05, raw_n)} | {mark(s05 <= 0.12 * raw_n)} |",
        f"| the 0.25 px figure | {_pct(s025, raw_n)} | (reported) |",
        f"| gzip <= 3% of raw (0.5 px) | {_pct(g05, raw_n)} | {mark(g05 <= 0.03 * raw_n)} |",
        *[f"| the same with `--smooth {k:g}` (max {v[2]:.2f} px from the unsmoothed input) | {_pct(v[0], raw_n)},"
          f" gzip {_pct(v[1], raw_n)} | {mark(v[0] <= 0.12 * raw_n)}, gzip {mark(v[1] <= 0.03 * raw_n)} |"
          for k, v in _SMOOTH.items()],
        f"| mobile <= 1.5 MB raw, <= 400 KB gzipped (0.25 px) | {m_raw / 1e6:.2f} MB, {m_gz / 1024:,.0f} KB |"
        f" {mark(m_raw <= 1.5e6 and m_gz <= 400 * 1024)} |",
        *[f"| mobile at {k:g} px | {v[0] / 1e6:.2f} MB, {v[1] / 1024:,.0f} KB |"
          f" {mark(v[0] <= 1.5e6 and v[1] <= 400 * 1024)} |" for k, v in _MOBILE.items() if not isinstance(k, tuple)
          and k != 0.25],
        *[f"| mobile, {k[0]:g} px + `--smooth {k[1]:g}` | {v[0] / 1e6:.2f} MB, {v[1] / 1024:,.0f} KB |"
          f" {mark(v[0] <= 1.5e6 and v[1] <= 400 * 1024)} |" for k, v in _MOBILE.items() if isinstance(k, tuple)],
        f"| >= 1,000,000 triangle-frames/s (writer, 0.25 px; rigid / plain) | {_SPEED[0.25][0] / 1e6:.2f} M /"
        f" {_SPEED[0.25][1] / 1e6:.2f} M | rigid {mark(_SPEED[0.25][0] >= 1e6)}, plain {mark(_SPEED[0.25][1] >= 1e6)} |",
    ]


if __name__ == "__main__":
    print(run())
