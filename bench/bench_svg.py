"""Small, exact animated SVG (issue 3): raw vs optimised sizes, gzip, generation speed, triangle budget,
the chapter's Table 12.5 beside ours, and the depth-order error against a z-buffer."""

from __future__ import annotations

import gzip
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.faces import _animated_face, chapter_face, face_region, ict_bench_face, ict_head
from bench.order_measure import order_error, robust_order
from converter import extract, formats
from converter.convert import convert_animation
from converter.encode import order
from converter.options import ConversionOptions, Report
from converter.verify import verify_animation
from converter.writers import svg_anim

TITLE = "Small, exact animated SVG (issue 3)"
SAMPLE = ROOT / "samples" / "face.glb"
OUT = ROOT / "bench" / "out"
REPEATS = 3


def _kb(n: int) -> str:
    return f"{n / 1024:,.0f}"


def _timed(fn, repeats: int = 1, cpu: bool = False):
    """Result and median seconds (wall clock, or this process's CPU time when cpu)."""
    clock = time.process_time if cpu else time.perf_counter
    times, out = [], None
    for _ in range(repeats):
        t = clock()
        out = fn()
        times.append(clock() - t)
    return out, statistics.median(times)


def measure(name: str, anim, size: int = 512) -> dict:
    """Everything for one face at one size."""
    row: dict = {"name": name, "frames": anim.n_frames, "fps": anim.fps, "triangles": anim.n_faces}
    options = ConversionOptions(size=size)
    cam = extract.fit_camera(anim, size)
    sheet, row["extract_s"] = _timed(lambda: extract.extract(anim, cam))
    row["paths"] = len(sheet.order)
    raw, row["raw_s"] = _timed(lambda: svg_anim.encode(sheet, options, Report(), "raw"))
    chapter, row["chapter_s"] = _timed(lambda: svg_anim.encode(sheet, options, Report(), "chapter"))
    report = Report()
    bounded, row["write_wall_s"] = _timed(lambda: svg_anim.write(sheet, options, report), REPEATS)
    _, row["write_s"] = _timed(lambda: svg_anim.write(sheet, options, Report()), REPEATS, cpu=True)
    row.update(raw=len(raw), chapter=len(chapter), bounded=len(bounded), gzip=len(gzip.compress(bounded, 9, mtime=0)),
               keys_per_path=report.figures["keys_per_path"], color_keys=report.counts["color_keys"])
    row["tf_per_s_paths"] = row["paths"] * anim.n_frames / row["write_s"]
    row["tf_per_s_input"] = anim.n_faces * anim.n_frames / row["write_s"]
    v = verify_animation(bounded, anim)
    row.update(max_px=v.max_px, mean_px=v.mean_px, vis_mismatch=v.visibility_mismatches)
    vc = verify_animation(chapter, anim)
    row["chapter_max_px"] = vc.max_px
    for tol in (0.1, 0.5, 1.0):
        data = svg_anim.write(sheet, ConversionOptions(size=size, tolerance=tol), Report())
        row[f"bounded_{tol}"] = len(data)
        row[f"max_px_{tol}"] = verify_animation(data, anim).max_px
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{name}.svg").write_bytes(bounded)
    row["_sheet"] = sheet
    return row


def mobile(anim, budget: int = 1500) -> dict:
    """The --max-triangles budget variant through the whole conversion."""
    result = convert_animation(anim, ConversionOptions(max_triangles=budget))
    r = result.report
    return {"svg": r.sizes["svg"], "gzip": len(gzip.compress(result.data, 9, mtime=0)),
            "triangles": r.counts.get("budget_triangles", anim.n_faces), "paths": r.counts["paths"],
            "dev": r.figures.get("budget_deviation_px", 0.0), "dev_mean": r.figures.get("budget_deviation_mean_px", 0.0),
            "dev_skin": r.figures.get("budget_deviation_px_skin", 0.0)}


def depth_rows(anim, sheet, label: str, which: list[int], with_layers: bool) -> list[str]:
    """Pixels whose front triangle differs from the z-buffer, per ordering."""
    rows = []
    fixed = order.draw_list(sheet)
    candidates = [("fixed neutral-frame order (default)", fixed)]
    robust = robust_order(sheet, sheet.order)
    candidates.append(("robust order (mean visible depth)", order.DrawList(robust, sheet.visible[:, robust])))
    if with_layers:
        t = time.perf_counter()
        lay = order.layered(sheet)
        candidates.append((f"layer copies (+{len(lay.triangles) - len(fixed.triangles)} paths, "
                           f"{time.perf_counter() - t:.0f} s)", lay))
    for title, dl in candidates:
        e = order_error(anim.frames, sheet, dl, which)
        rows.append(f"| {label} | {title} | {100 * e['mean']:.2f}% | {100 * e['max']:.2f}% |")
    oracle = []
    for k in which:
        o = sheet.order[np.argsort(-sheet.depth[k][sheet.faces[sheet.order]].mean(axis=1), kind="stable")]
        oracle.append(order_error(anim.frames, sheet, order.DrawList(o, sheet.visible[:, o]), [k])["max"])
    rows.append(f"| {label} | per-frame painter's sort (bound for one order per frame) | "
                f"{100 * np.mean(oracle):.2f}% | {100 * max(oracle):.2f}% |")
    return rows


def run() -> str:
    faces = [("ict_bench_face", ict_bench_face())]
    if SAMPLE.exists():
        faces.append(("bundled sample", formats.load(SAMPLE)))
    rows = {name: measure(name.replace(" ", "_"), anim) for name, anim in faces}
    chap_anim = chapter_face()
    chap = measure("chapter_face", chap_anim)
    mob = {name: mobile(anim) for name, anim in faces}
    out = ["All at 512 px, default options (tolerance 0.25 px). Sizes in KB (1024 bytes) of the uncompressed SVG; "
           "gzip -9 of the optimised file. `raw` = every frame, 2 decimals (the chapter's unoptimised encoding); "
           "`chapter` = the chapter's post-optimisations (no coordinates while hidden, still runs merged with "
           "keyTimes, exact to 2 decimals); `ours` = error-bounded keys. Max/mean px: `facesvg verify` (SMIL evaluated "
           f"at every frame against the exact projection). Write time: median of {REPEATS} runs of the writer on the "
           "extracted sheet (after loading and extraction), as CPU time of the process (the machine is shared by "
           "several jobs, so wall time in brackets varies with their load); triangle-frames/s = drawn paths x "
           "frames / CPU s (input triangles x frames in brackets).", ""]
    out.append("| face | frames | triangles (drawn) | raw KB | chapter KB (%) | ours KB (% raw) | gzip KB (% raw) | "
               "max / mean px | keys per path | write CPU s (wall) | triangle-frames/s |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in list(rows.values()) + [chap]:
        out.append(
            f"| {r['name']} | {r['frames']} | {r['triangles']} ({r['paths']}) | {_kb(r['raw'])} | "
            f"{_kb(r['chapter'])} ({100 * r['chapter'] / r['raw']:.0f}%) | {_kb(r['bounded'])} "
            f"({100 * r['bounded'] / r['raw']:.1f}%) | {_kb(r['gzip'])} ({100 * r['gzip'] / r['raw']:.2f}%) | "
            f"{r['max_px']:.3f} / {r['mean_px']:.3f} | {r['keys_per_path']:.1f} of {r['frames']} | "
            f"{r['write_s']:.2f} ({r['write_wall_s']:.2f}) | "
            f"{r['tf_per_s_paths'] / 1e6:.2f} M ({r['tf_per_s_input'] / 1e6:.2f} M) |")
    out += ["", "Size against tolerance (KB, % of raw, verified max px):", "",
            "| face | 0.1 px | 0.25 px | 0.5 px | 1 px |", "|---|---|---|---|---|"]
    for r in list(rows.values()) + [chap]:
        cells = []
        for tol in (0.1, 0.25, 0.5, 1.0):
            size = r["bounded"] if tol == 0.25 else r[f"bounded_{tol}"]
            mx = r["max_px"] if tol == 0.25 else r[f"max_px_{tol}"]
            cells.append(f"{_kb(size)} ({100 * size / r['raw']:.1f}%, {mx:.3f})")
        out.append(f"| {r['name']} | " + " | ".join(cells) + " |")
    out += ["", "Mobile variant `--max-triangles 1500` (whole conversion; deviation = max px distance of every original "
            "vertex of a front-facing triangle from the simplified surface over all frames; skin only in brackets):",
            "", "| face | triangles -> kept | SVG KB | gzip KB | max (skin) / mean deviation px |", "|---|---|---|---|---|"]
    for name, m in mob.items():
        out.append(f"| {name} | {rows[name]['triangles']} -> {m['triangles']} ({m['paths']} drawn) | {_kb(m['svg'])} | "
                   f"{_kb(m['gzip'])} | {m['dev']:.1f} ({m['dev_skin']:.1f}) / {m['dev_mean']:.2f} |")
    out += ["", "The chapter's Table 12.5 beside ours (face of ~484 polygons, 8.28 s at 25 fps; ours: "
            "`bench.faces.chapter_face`, 512 px; generation = writer seconds on this machine):", "",
            "| | # polys | duration s | raw KB | optim KB | generation s |", "|---|---|---|---|---|---|",
            "| chapter, Face | 484 | 8.28 | 5684 | 4798 (84%) | 8 |",
            f"| ours, raw / chapter's optimisations | {chap['triangles']} ({chap['paths']} drawn) | "
            f"{chap['frames'] / chap['fps']:.2f} | {_kb(chap['raw'])} | {_kb(chap['chapter'])} "
            f"({100 * chap['chapter'] / chap['raw']:.0f}%) | {chap['raw_s']:.2f} / {chap['chapter_s']:.2f} |",
            f"| ours, error-bounded 0.25 px | | | | {_kb(chap['bounded'])} ({100 * chap['bounded'] / chap['raw']:.1f}%) | "
            f"{chap['write_s']:.2f} |"]
    bench = rows["ict_bench_face"]
    bench_anim = faces[0][1]
    which = list(range(0, bench["frames"], max(1, bench["frames"] // 6)))[:6]
    turn = _animated_face(face_region(ict_head(), 6000), 60, 30.0, yaw_deg=40.0, pitch_deg=10.0, name="turn40")
    turn_sheet = extract.extract(turn, extract.fit_camera(turn, 512), occlusion=False)
    out += ["", "Depth order: share of covered pixels whose front triangle in the SVG (resvg, ids as colours) is not the "
            "z-buffer's (pyrender) within one pixel, mean and max over 6 frames:", "",
            "| face | order | mean | max |", "|---|---|---|---|"]
    out += depth_rows(bench_anim, bench["_sheet"], "ict_bench_face (yaw +-15, pitch +-10)", which, False)
    out += depth_rows(turn, turn_sheet, "ICT face, yaw +-40 (60 frames)", [0, 10, 20, 30, 40, 50], False)
    out += depth_rows(chap_anim, chap["_sheet"], "chapter_face", [0, 40, 80, 120, 160, 200], True)
    m_bench = mob["ict_bench_face"]
    targets = [
        ("optimised <= 10% of raw at <= 0.25 px (ict_bench_face)", f"{100 * bench['bounded'] / bench['raw']:.1f}%, "
         f"max {bench['max_px']:.3f} px", bench["bounded"] <= 0.10 * bench["raw"] and bench["max_px"] <= 0.25),
        ("gzip <= 3% of raw (ict_bench_face)", f"{100 * bench['gzip'] / bench['raw']:.2f}%", bench["gzip"] <= 0.03 * bench["raw"]),
        ("generation >= 1,000,000 triangle-frames/s (ict_bench_face, drawn paths, CPU time)",
         f"{bench['tf_per_s_paths'] / 1e6:.2f} M/s", bench["tf_per_s_paths"] >= 1e6),
        ("--max-triangles 1500 variant < 1 MB uncompressed (ict_bench_face)", f"{_kb(m_bench['svg'])} KB",
         m_bench["svg"] < 1024 * 1024),
    ]
    if "bundled sample" in rows:
        s = rows["bundled sample"]
        targets += [
            ("optimised <= 10% of raw at <= 0.25 px (bundled sample)", f"{100 * s['bounded'] / s['raw']:.1f}%, max "
             f"{s['max_px']:.3f} px", s["bounded"] <= 0.10 * s["raw"] and s["max_px"] <= 0.25),
            ("gzip <= 3% of raw (bundled sample)", f"{100 * s['gzip'] / s['raw']:.2f}%", s["gzip"] <= 0.03 * s["raw"]),
            ("--max-triangles 1500 variant < 1 MB (bundled sample)", f"{_kb(mob['bundled sample']['svg'])} KB",
             mob["bundled sample"]["svg"] < 1024 * 1024),
        ]
    out += ["", "Targets of the issue:", "", "| target | measured | |", "|---|---|---|"]
    out += [f"| {t} | {m} | {'met' if ok else 'missed'} |" for t, m, ok in targets]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    print(run())
