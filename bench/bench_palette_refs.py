"""Which reference to a shared animated colour plays fastest (issue 49, item 2), and which draws frame 0 without SMIL.

The same paths and the same `d` animations in every document, from our pipeline on the bundled sample: N = 300 is
`--preset mobile` (256 px, merged paths, 300 animated elements), N = 1500 the first 1,500 paths (draw order) of
`color_tolerance=255` at the default 512 px (one triangle a path). Every path gets a palette entry (seeded);
each of the K palette colours has its own discrete track of STEPS held colours over the sample's duration. Only
the way a path refers to its colour changes (VARIANTS). Each document plays from a loopback server in headless
Chromium (1x and 4x CPU throttling, as a document and inside `<img>`), Firefox ESR and WebKitGTK (unthrottled,
as a document); rAF callbacks a second over PLAY_S after WARM_S of play. A colour-only probe (the variant's colours
without `d` animations) checks that the colours really play in each engine and mode (pixels change between two
shots). Frame 0 where SMIL and CSS animations are ignored: each variant rendered by resvg, CairoSVG and
rsvg-convert against the static colours in the same layout. `var` is probed and rendered but not timed (TIMED).
"""

from __future__ import annotations

import copy
import functools
import hashlib
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.playback import chromium, host_page, installed_engines, measure, serve, session_fps
from converter.convert import convert
from converter.options import ConversionOptions
from tests.conftest import SAMPLE
from tests.engines import colour_difference

TITLE = "Shared animated colours: which reference plays fastest (issue 49)"
SVG = "http://www.w3.org/2000/svg"
CASES = ((300, 32), (1500, 128))  # (paths N, palette colours K): two cases keep the run near ten minutes
STEPS = 20  # held colours per palette track over the duration
WARM_S, PLAY_S = 1.0, 5.0
THROTTLES = (1, 4)
PROBE_GAP_S = 0.7  # between the two shots that tell whether the colours play
SEED = 49
# name -> what it is (the table's legend); builders below
VARIANTS = {
    "static": "static colours (`.cK{color}` classes, `fill:currentColor`): the floor",
    "own": "today's: each path its own discrete `<animate attributeName=\"color\">`",
    "group": "paths under one `<g class=\"cK\">` per palette colour whose `color` animates (SMIL); paths "
             "`fill:currentColor`",
    "gradient": "`fill=\"url(#pK)\" stroke=\"url(#pK)\"`, a one-stop `<linearGradient>` (userSpaceOnUse) whose "
                "`stop-color` animates (SMIL)",
    "css": "each path `class=\"cK\"`, `.cK{animation:kK ... step-end infinite}` (CSS `@keyframes` on `color`)",
    "css-group": "as `group`, but the `<g class=\"cK\">` animates `color` by CSS `@keyframes`",
    "var": "`@property --cK` (`<color>`) animated by CSS on the root `<svg>`; paths `fill:var(--cK,#frame0)`",
}
# `var` draws frame 0 black in resvg and rsvg-convert and crashes CairoSVG (the frame-0 table), so it is not timed.
TIMED = ("static", "own", "group", "gradient", "css", "css-group")
RENDERERS = ("resvg", "CairoSVG", "rsvg-convert")


class Source(NamedTuple):
    """A pipeline SVG reduced to geometry: its root attributes, seam stroke width, duration and element tree."""

    root: ET.Element  # the <svg> with every group and path, colours and ids removed
    stroke_width: str
    dur: str


class Palette(NamedTuple):
    """K discrete colour tracks (each its own key times) and which entry each of N paths uses."""

    key_times: list[str]  # per entry, "0;.05;..."
    values: list[list[str]]  # per entry, STEPS hex colours
    of_path: np.ndarray  # (N,) entry index


@functools.cache
def source(n: int) -> Source:
    """The sample converted by our pipeline (the mobile preset for n <= 300, else the default with static colours),
    cut to n paths, colour classes and animations stripped."""
    opts = ConversionOptions.given(preset="mobile") if n <= 300 else ConversionOptions(color_tolerance=255.0)
    ET.register_namespace("", SVG)
    root = ET.fromstring(convert(SAMPLE, opts).data)
    style = root.find(f"{{{SVG}}}style").text
    width = style.split("stroke-width:", 1)[1].split(";", 1)[0]
    for tag in ("metadata", "title", "style"):
        for e in root.findall(f"{{{SVG}}}{tag}"):
            root.remove(e)
    kept, dur = 0, ""
    for parent in list(root.iter()):
        for e in list(parent):
            if e.tag != f"{{{SVG}}}path":
                continue
            if kept >= n:
                parent.remove(e)
                continue
            kept += 1
            e.attrib.pop("id", None)
            seam = "n" in e.get("class", "").split()
            e.attrib.pop("class", None)
            if seam:
                e.set("class", "n")
            for a in list(e):
                if a.get("attributeName") != "d":
                    e.remove(a)
                else:
                    dur = a.get("dur")
    return Source(root, width, dur)


def palette(n: int, k: int, rng: np.random.Generator) -> Palette:
    """K skin-like colour tracks of STEPS held colours at random key times (seeded), and a random entry per path."""
    frames = 121
    times, values = [], []
    for _ in range(k):
        picks = np.sort(rng.choice(np.arange(1, frames - 1), STEPS - 1, replace=False))
        times.append(";".join(["0"] + [f"{t / (frames - 1):.3g}".lstrip("0") for t in picks]))
        base = np.array((120.0, 80.0, 70.0)) + rng.uniform() * np.array((125.0, 135.0, 130.0))
        base += rng.uniform(-15, 15, 3)
        walk = np.cumsum(rng.choice((-1, 1), (STEPS, 3)) * rng.uniform(4, 14, (STEPS, 3)), axis=0)
        rgb = np.clip(np.round(base + walk), 0, 255).astype(int)
        values.append(["#" + "".join(f"{int(x):02x}" for x in c) for c in rgb])
    return Palette(times, values, rng.integers(0, k, n))


def _paths(root: ET.Element) -> list[tuple[ET.Element, ET.Element]]:
    """(parent, path) in document order."""
    return [(parent, e) for parent in root.iter() for e in parent if e.tag == f"{{{SVG}}}path"]


def _smil(attribute: str, dur: str, key_times: str, values: list[str]) -> ET.Element:
    return ET.Element(f"{{{SVG}}}animate", {"attributeName": attribute, "calcMode": "discrete", "dur": dur,
                                             "repeatCount": "indefinite", "keyTimes": key_times,
                                             "values": ";".join(values)})


def _keyframes(name: str, prop: str, key_times: str, values: list[str]) -> str:
    """CSS @keyframes holding each value from its key time to the next (with step-end timing)."""
    stops = [f"{float(t) * 100:.4g}%{{{prop}:{v}}}" for t, v in zip(key_times.split(";"), values)]
    return f"@keyframes {name}{{{''.join(stops)}100%{{{prop}:{values[-1]}}}}}"


def _set_class(e: ET.Element, name: str) -> None:
    e.set("class", " ".join([name] + e.get("class", "").split()))


def _group(root: ET.Element, pal: Palette, make: Callable[[int], ET.Element]) -> None:
    """Move each parent's paths into one child group per palette entry (made by make(k)), draw order ignored."""
    by_parent: dict[int, tuple[ET.Element, dict[int, list[ET.Element]]]] = {}
    for i, (parent, e) in enumerate(_paths(root)):
        by_parent.setdefault(id(parent), (parent, {}))[1].setdefault(int(pal.of_path[i]), []).append(e)
    for parent, buckets in by_parent.values():
        for k, members in sorted(buckets.items()):
            g = make(k)
            for e in members:
                parent.remove(e)
                g.append(e)
            parent.append(g)


def document(src: Source, pal: Palette, variant: str, animate_geometry: bool = True) -> bytes:
    """The source's geometry with the palette referred to as `variant` says (see VARIANTS); without its `d` and
    group transform animations if not animate_geometry."""
    root = copy.deepcopy(src.root)
    if not animate_geometry:
        for parent in list(root.iter()):
            for e in list(parent):
                if e.tag in (f"{{{SVG}}}animate", f"{{{SVG}}}animateTransform"):
                    parent.remove(e)
    base = (f"path{{stroke-width:{src.stroke_width};stroke-linejoin:round;stroke-linecap:round}}"
            "path{fill:currentColor;stroke:currentColor}")
    k_all = range(len(pal.values))
    frame0 = "".join(f".c{k}{{color:{pal.values[k][0]}}}" for k in k_all)
    css, head = "", []
    if variant in ("static", "own", "css"):
        css = base + frame0
        for i, (_, e) in enumerate(_paths(root)):
            k = int(pal.of_path[i])
            _set_class(e, f"c{k}")
            if variant == "own":
                e.append(_smil("color", src.dur, pal.key_times[k], pal.values[k]))
        if variant == "css":
            css += "".join(_keyframes(f"k{k}", "color", pal.key_times[k], pal.values[k]) for k in k_all)
            css += "".join(f".c{k}{{animation:k{k} {src.dur} step-end infinite}}" for k in k_all)
    elif variant in ("group", "css-group", "static-grouped"):
        css = base + frame0

        def make(k: int) -> ET.Element:
            g = ET.Element(f"{{{SVG}}}g", {"class": f"c{k}"})
            if variant == "group":
                g.append(_smil("color", src.dur, pal.key_times[k], pal.values[k]))
            return g

        _group(root, pal, make)
        if variant == "css-group":
            css += "".join(_keyframes(f"k{k}", "color", pal.key_times[k], pal.values[k]) for k in k_all)
            css += "".join(f"g.c{k}{{animation:k{k} {src.dur} step-end infinite}}" for k in k_all)
    elif variant == "gradient":
        css = f"path{{stroke-width:{src.stroke_width};stroke-linejoin:round;stroke-linecap:round}}"
        defs = ET.Element(f"{{{SVG}}}defs")
        for k in k_all:
            grad = ET.SubElement(defs, f"{{{SVG}}}linearGradient", {"id": f"p{k}", "gradientUnits": "userSpaceOnUse"})
            stop = ET.SubElement(grad, f"{{{SVG}}}stop", {"stop-color": pal.values[k][0]})
            stop.append(_smil("stop-color", src.dur, pal.key_times[k], pal.values[k]))
        head.append(defs)
        for i, (_, e) in enumerate(_paths(root)):
            k = int(pal.of_path[i])
            e.set("fill", f"url(#p{k})")
            e.set("stroke", f"url(#p{k})")
    elif variant == "var":
        css = f"path{{stroke-width:{src.stroke_width};stroke-linejoin:round;stroke-linecap:round}}"
        css += "".join(f"@property --c{k}{{syntax:'<color>';inherits:true;initial-value:{pal.values[k][0]}}}"
                       for k in k_all)
        css += "".join(_keyframes(f"k{k}", f"--c{k}", pal.key_times[k], pal.values[k]) for k in k_all)
        css += "svg{animation:" + ",".join(f"k{k} {src.dur} step-end infinite" for k in k_all) + "}"
        css += "".join(f".c{k}{{fill:var(--c{k},{pal.values[k][0]});stroke:var(--c{k},{pal.values[k][0]})}}"
                       for k in k_all)
        for i, (_, e) in enumerate(_paths(root)):
            _set_class(e, f"c{int(pal.of_path[i])}")
    else:
        raise ValueError(f"unknown variant {variant}")
    style = ET.Element(f"{{{SVG}}}style")
    style.text = css + ".n{stroke:none}"
    for i, e in enumerate([style] + head):
        root.insert(i, e)
    return ET.tostring(root, encoding="unicode").encode()


def _png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))


def render_static(renderer: str, svg: bytes) -> np.ndarray | None:
    """RGBA frame 0 as a renderer that ignores SMIL and CSS animations draws it (None: renderer missing)."""
    if renderer == "resvg":
        import resvg_py

        return _png(bytes(resvg_py.svg_to_bytes(svg_string=svg.decode())))
    if renderer == "CairoSVG":
        try:
            import cairosvg
        except (ImportError, OSError):
            return None
        return _png(cairosvg.svg2png(bytestring=svg))
    exe = shutil.which("rsvg-convert")
    if not exe:
        return None
    return _png(subprocess.run([exe, "--format=png"], input=svg, capture_output=True, check=True).stdout)


GROUPED = ("group", "css-group")  # variants whose paths are regrouped (draw order changed)


def frame0_table(docs: dict[str, bytes]) -> tuple[str, dict[str, float]]:
    """Markdown rows: each variant's frame 0 in each static renderer against the static colours in the same layout
    (`static-grouped` for the regrouped variants, `static` for the others; `static-grouped` itself against
    `static`), and per variant the worst mean colour difference over renderers (255: fails or draws < 90 %)."""
    rows, worst = [], {}
    refs = {(r, name): render_static(r, docs[name]) for r in RENDERERS for name in ("static", "static-grouped")}
    for variant, svg in docs.items():
        if variant == "static":
            continue
        layout = "static-grouped" if variant in GROUPED else "static"
        cells = []
        for r in RENDERERS:
            ref = refs[(r, layout)]
            if ref is None:
                cells.append("missing")
                continue
            try:
                got = render_static(r, svg)
            except Exception as exc:  # a renderer that fails on the markup is the finding
                cells.append(f"fails ({type(exc).__name__})")
                worst[variant] = 255.0
                continue
            drawn = ref[..., 3] > 127
            covered = float((got[..., 3] > 127)[drawn].mean())
            diff = colour_difference(got, ref)
            worst[variant] = max(worst.get(variant, 0.0), diff if covered > 0.9 else 255.0)
            cells.append(f"{diff:.2f} / {covered:.3f}")
        rows.append(f"| {variant} | {layout if variant != 'static-grouped' else 'static'} | " + " | ".join(cells) + " |")
    return "\n".join(rows), worst


def _changes(shoot: Callable[[], bytes], gap: float) -> bool:
    """Whether two shots `gap` seconds apart differ."""
    a = hashlib.sha1(shoot()).hexdigest()
    time.sleep(gap)
    return a != hashlib.sha1(shoot()).hexdigest()


def chromium_plays(browser, url: str, size: int) -> bool:
    """Whether a colour-only probe changes pixels in Chromium (document or host page)."""
    page = browser.new_page(viewport={"width": size, "height": size})
    try:
        page.goto(url, wait_until="load")
        page.wait_for_timeout(300)
        return _changes(lambda: page.screenshot(animations="allow"), PROBE_GAP_S)
    finally:
        page.close()


def load_note() -> str:
    """The machine's load averages now."""
    one, five, _ = os.getloadavg()
    return f"{one:.2f} (1 min) / {five:.2f} (5 min)"


def run() -> str:
    rng = np.random.default_rng(SEED)
    load_before = load_note()
    t_start = time.perf_counter()
    cases = []  # (paths, palette colours, px, {variant: svg})
    for n, k in CASES:
        src = source(n)
        n_real = len(_paths(src.root))
        pal = palette(n_real, k, rng)
        cases.append((n_real, k, int(src.root.get("width")), {v: document(src, pal, v) for v in TIMED}))
    # the probe: N=300, K=32 colours without geometry animations, so that pixels change only if the colours play
    probe_src = source(300)
    probe_pal = palette(len(_paths(probe_src.root)), 32, np.random.default_rng(SEED + 1))
    probes = {v: document(probe_src, probe_pal, v, animate_geometry=False) for v in VARIANTS}
    fps: dict[tuple[int, str, str], float | None] = {}  # (case, variant, column) -> rAF fps
    changed: dict[tuple[int, str, str], float] = {}  # Chromium screencast frames changed a second
    plays: dict[tuple[str, str], bool] = {}  # (variant, column group) -> colours change pixels
    columns = [f"Chromium {r}x {m}" for m in ("doc", "img") for r in THROTTLES] + ["Firefox ESR", "WebKitGTK"]
    notes = []
    with tempfile.TemporaryDirectory() as tmp, serve(Path(tmp)) as base:
        folder = Path(tmp)
        for c, (_, _, size, docs) in enumerate(cases):
            for v, data in docs.items():
                (folder / f"c{c}_{v}.svg").write_bytes(data)
                (folder / f"c{c}_{v}.html").write_text(host_page(f"c{c}_{v}.svg", size))
        probe_size = int(probe_src.root.get("width"))
        for v, data in probes.items():
            (folder / f"probe_{v}.svg").write_bytes(data)
            (folder / f"probe_{v}.html").write_text(host_page(f"probe_{v}.svg", probe_size))
        with chromium() as browser:
            for v in VARIANTS:
                plays[(v, "Chromium doc")] = chromium_plays(browser, f"{base}/probe_{v}.svg", probe_size)
                plays[(v, "Chromium img")] = chromium_plays(browser, f"{base}/probe_{v}.html", probe_size)
            # variants innermost: a column's cells are measured within a minute of each other (the load drifts)
            for c, (_, _, size, _) in enumerate(cases):
                for mode, ext in (("doc", "svg"), ("img", "html")):
                    for rate in THROTTLES:
                        col = f"Chromium {rate}x {mode}"
                        for v in TIMED:
                            got = measure(browser, f"{base}/c{c}_{v}.{ext}", size, rate, PLAY_S, 120.0, warm=WARM_S)
                            fps[(c, v, col)] = got.fps_raf if got else None
                            changed[(c, v, col)] = got.fps_changed if got else 0.0
                        print(f"case {c} {col}: " + ", ".join(f"{v} {fps[(c, v, col)]}" for v in TIMED), flush=True)
        engines, missing = installed_engines()
        notes += missing
        for name, launch in engines:
            with launch() as session:
                for v in VARIANTS:
                    session.navigate(f"{base}/probe_{v}.svg")
                    time.sleep(0.3)
                    plays[(v, name)] = _changes(lambda: session.png("svg"), PROBE_GAP_S)
                for c in range(len(cases)):
                    # the better of two runs, the variants in one order then the other: other jobs only slow a run
                    for order in (TIMED, TIMED[::-1]):
                        for v in order:
                            got = session_fps(session, f"{base}/c{c}_{v}.svg", WARM_S, PLAY_S)
                            fps[(c, v, name)] = max(got, fps.get((c, v, name), 0.0))
                    print(f"case {c} {name}: " + ", ".join(f"{fps[(c, v, name)]:.1f}" for v in TIMED), flush=True)
    seconds = time.perf_counter() - t_start
    shown = [col for col in columns if any((0, v, col) in fps for v in TIMED)]
    table = []
    for c, (n, k, size, docs) in enumerate(cases):
        for v, data in docs.items():
            cells = []
            for col in shown:
                got = fps.get((c, v, col))
                cell = "-" if got is None else f"{got:.1f}"
                if col.startswith("Chromium") and got is not None:
                    cell += f" ({changed[(c, v, col)]:.0f})"
                cells.append(cell)
            table.append(f"| {n} | {k} | {size} | {v} | {len(data) / 1024:,.0f} | " + " | ".join(cells) + " |")
    play_cols = ["Chromium doc", "Chromium img"] + [name for name in ("Firefox ESR", "WebKitGTK")
                                                    if (next(iter(VARIANTS)), name) in plays]
    play_rows = [f"| {v} | " + " | ".join("yes" if plays[(v, col)] else "**no**" for col in play_cols) + " |"
                 for v in VARIANTS]
    src0 = source(CASES[0][0])
    pal0 = palette(len(_paths(src0.root)), CASES[0][1], np.random.default_rng(SEED))
    f0_docs = {v: document(src0, pal0, v) for v in list(VARIANTS) + ["static-grouped"]}
    f0_rows, f0_worst = frame0_table(f0_docs)
    summary = []
    for c, (n, k, _, _) in enumerate(cases):
        for col in shown:
            group = col if not col.startswith("Chromium") else "Chromium " + col.rsplit(" ", 1)[1]
            fair = [v for v in TIMED if v != "static" and f0_worst.get(v, 255.0) < 1.0 and plays.get((v, group))
                    and fps.get((c, v, col)) is not None]
            if not fair:
                continue
            best = max(fair, key=lambda v: fps[(c, v, col)])
            own, floor = fps.get((c, "own", col)), fps.get((c, "static", col))
            summary.append(f"| {n} | {k} | {col} | {best} | {fps[(c, best, col)]:.1f} | "
                           f"{'-' if own is None else f'{own:.1f}'} | {'-' if floor is None else f'{floor:.1f}'} | "
                           + ", ".join(f"{v} {fps[(c, v, col)]:.1f}" for v in sorted(
                               fair, key=lambda v: -fps[(c, v, col)]) if v != best) + " |")
    return (
        f"Geometry from our pipeline on the bundled sample: the `d` animations (linear, as the writer keys them) "
        f"of {cases[0][0]} merged paths of `--preset mobile` ({cases[0][2]} px) and of the first {cases[-1][0]} "
        f"paths (one triangle each) of the default with static colours ({cases[-1][2]} px); K palette "
        f"colours, each a discrete track of {STEPS} held colours at its own random key times (seed {SEED}); each "
        f"path a random entry. Variants:\n\n" + "\n".join(f"- `{v}`: {d}" for v, d in VARIANTS.items()) + "\n\n"
        f"Cells: requestAnimationFrame callbacks a second over {PLAY_S:g} s after {WARM_S:g} s of play; one run "
        "in Chromium, the better of two (the variants in one order, then the reverse) in Firefox and WebKit; "
        "Chromium cells add (screencast frames whose pixels changed a second; inside `<img>` the host page's rAF "
        "overstates playback). Headless Chromium (SwiftShader; 4x = DevTools CPU throttling), Firefox ESR headless, "
        "WebKitGTK MiniBrowser on Xvfb; all documents from a loopback server. Load average before the run "
        f"{load_before}, after {load_note()} (2 cores, shared with other jobs: single runs scatter); the browser "
        f"part took {seconds:.0f} s.\n\n"
        "| N | K | px | variant | KB | " + " | ".join(shown) + " |\n|---|---|---|---|---|" + "---|" * len(shown) + "\n"
        + "\n".join(table) + "\n\n"
        f"Do the colours play? A probe per variant ({len(_paths(probe_src.root))} paths, 32 colours, no `d` "
        f"or group transform animation): two shots {PROBE_GAP_S:g} s apart differ (the `static` row must say no).\n\n"
        "| variant | " + " | ".join(play_cols) + " |\n|---|" + "---|" * len(play_cols) + "\n"
        + "\n".join(play_rows) + "\n\n"
        f"Frame 0 where animations are ignored (N = {cases[0][0]}, K = {cases[0][1]}): mean RGB difference "
        "(8-bit levels) to the static colours' render in the same layout where both are opaque / share of that "
        "render's opaque pixels the variant covers. `static-grouped` is `static` regrouped as `group` (draw order "
        "changed, colours static); its row against `static` is what regrouping alone changes (seam strokes and "
        "overlaps drawn in another order), which a real writer avoids by grouping only runs of the draw order.\n\n"
        "| variant | against | " + " | ".join(RENDERERS) + " |\n|---|---|---|---|---|\n" + f0_rows + "\n"
        + "\n\nFastest colour-animating variant per case and engine among those whose colours play there (the "
        "probe) and that draw frame 0 right in all three static renderers (difference < 1 level in the same "
        "layout), against `own` (today's) and the `static` floor (rAF fps as above):\n\n"
        "| N | K | engine | fastest | fps | own | static | the others |\n|---|---|---|---|---|---|---|---|\n"
        + "\n".join(summary) + "\n"
        + "".join(f"\n- {note}" for note in notes)
    )


if __name__ == "__main__":
    print(run())
