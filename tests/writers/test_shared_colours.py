"""The default flat SVG: shared animated colours (one-stop gradients whose stop colour animates once each) and
paths of one shared colour merged; read back from the file, every triangle plays within the colour tolerance.

The structure checks guard what makes the default play (issue 49): far fewer elements than triangles, no
element animating its own colour, one animation per animated palette entry."""

from __future__ import annotations

import re

import numpy as np
import pytest
from lxml import etree

from converter import formats
from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.verify import evaluate, verify_animation
from converter.writers import svg_anim

SVG = "{http://www.w3.org/2000/svg}"


@pytest.fixture(scope="module")
def sample(sample_path):
    anim = formats.load(sample_path).sliced(0, 40)
    return anim, extract(anim, fit_camera(anim, 192))


def _hex(text: str) -> np.ndarray:
    return np.array([int(text[i:i + 2], 16) for i in (1, 3, 5)], np.float64)


def played_colours(data: bytes, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Per drawn triangle (evaluate's order) its played levels (T, P, 3), read from the document alone: a path's
    class names a static colour (.cN{color}) or a gradient (.pN{fill:url(#pN)}) whose one stop's discrete
    stop-color animation plays; each path's subpaths take its colour."""
    root = etree.fromstring(data)
    css = "".join(s.text for s in root.iter(f"{SVG}style"))
    static = {m[0]: _hex(m[1]) for m in re.findall(r"\.(c\d+)\{color:(#[0-9a-f]{6})\}", css)}
    refs = dict(re.findall(r"\.(p\d+)\{fill:url\(#(p\d+)\);stroke:url\(#p\d+\)\}", css))
    frames = np.arange(n_frames) / n_frames
    tracks = {}
    for g in root.iter(f"{SVG}linearGradient"):
        stops = g.findall(f"{SVG}stop")
        assert len(stops) == 1
        anims = stops[0].findall(f"{SVG}animate")
        assert len(anims) == 1 and anims[0].get("calcMode") == "discrete"
        times = np.array([float(x) for x in anims[0].get("keyTimes").split(";")])
        values = np.array([_hex(v) for v in anims[0].get("values").split(";")])
        assert (values[0] == _hex(stops[0].get("stop-color"))).all()  # the static stop is frame 0
        tracks[g.get("id")] = values[np.searchsorted(times, frames, side="right") - 1]
    out = []
    for el in root.iter(f"{SVG}path"):
        names = el.get("class").split()
        colour = next((np.broadcast_to(static[n], (n_frames, 3)) for n in names if n in static), None)
        if colour is None:
            colour = next(tracks[refs[n]] for n in names if n in refs)
        assert el.find(f"{SVG}animate[@attributeName='color']") is None  # no path animates its own colour
        out += [colour] * len(re.findall(r"[mM]", el.get("d")))
    return np.stack(out, axis=1), np.array(sorted(tracks))


def test_default_plays_every_triangle_within_the_colour_tolerance_and_the_bound(sample):
    anim, sheet = sample
    report = Report()
    data = svg_anim.write(sheet, ConversionOptions(size=192), report)
    v = verify_animation(data, anim)
    assert v.ok and v.max_px <= 0.25, v.summary()
    ev = evaluate(data)
    colours, gradients = played_colours(data, sheet.n_frames)
    assert colours.shape[1] == len(ev.triangles)
    exact = sheet.face_colors(ev.triangles).astype(np.float64) * 255
    err = np.abs(colours - exact).max(axis=2)[ev.shown]
    assert err.max() <= ConversionOptions().color_tolerance
    assert err.max() == pytest.approx(report.figures["color_error_max_levels"], abs=0.01)
    assert len(gradients) == report.counts["shared_color_animations"] > 0


def test_default_structure_elements_per_triangle_and_colour_animations_per_entry(sample):
    """What makes the default play: merged paths, each animated palette colour animated once."""
    _, sheet = sample
    shared, exact = Report(), Report()
    data = svg_anim.write(sheet, ConversionOptions(size=192), shared)
    svg_anim.write(sheet, ConversionOptions(size=192, exact=True), exact)
    triangles = len(evaluate(data).triangles)
    paths = data.count(b"<path ")
    assert paths == shared.counts["paths"] <= 0.7 * triangles  # merged (unstroked paths stay alone)
    assert exact.counts["paths"] == triangles  # exact: one path per triangle
    assert shared.counts["color_animations"] == 0 and exact.counts["color_animations"] > 0
    gradients = data.count(b"<linearGradient")
    entries = shared.counts["palette_entries"]
    assert gradients == shared.counts["shared_color_animations"] <= entries < triangles
    assert data.count(b'attributeName="stop-color"') == gradients  # one animation per animated entry
    ids = re.findall(rb'<linearGradient id="(p\d+)"', data)
    assert len(set(ids)) == len(ids)  # none twice
    assert all(re.search(rb'class="' + i + rb'[ "]', data) for i in ids)  # each referred to by a path
    assert shared.figures["playback_ms_4x"] < exact.figures["playback_ms_4x"]


def test_exact_keeps_todays_file(sample):
    """--exact is the former default: each triangle its own path and colour steps within 3 levels."""
    _, sheet = sample
    report = Report()
    data = svg_anim.write(sheet, ConversionOptions(size=192, exact=True), report)
    assert b"<linearGradient" not in data and b'attributeName="color"' in data
    assert report.figures["color_error_max_levels"] <= 3.0
    assert ConversionOptions(exact=True).color_tolerance == 3.0
    assert ConversionOptions.given(exact=True, color_tolerance=8.0).color_tolerance == 8.0


def test_wider_colour_tolerance_fewer_entries_and_elements(sample):
    _, sheet = sample
    counts = []
    for tol in (4.0, 8.0, 16.0):
        r = Report()
        svg_anim.write(sheet, ConversionOptions(size=192, color_tolerance=tol), r)
        assert r.figures["color_error_max_levels"] <= tol
        counts.append((r.counts["palette_entries"], r.counts["paths"]))
    assert counts[0][0] > counts[1][0] > counts[2][0]
    assert counts[0][1] >= counts[1][1] >= counts[2][1]


def test_unstroked_paths_stay_unstroked_under_a_shared_colour(sample):
    """`.n{stroke:none}` (paths with more than one outline edge, seams.py) must win over an entry's stroke paint:
    with equal specificity the later rule wins, and a stroked outline fattened the robot's limbs (IoU 0.977 against
    three.js)."""
    _, sheet = sample
    data = svg_anim.write(sheet, ConversionOptions(size=192), Report()).decode()
    style = re.search(r"<style>(.*?)</style>", data).group(1)
    assert re.search(r'class="p\d+ n"', data)  # the case exists
    last_entry = max(m.end() for m in re.finditer(r"\.p\d+\{[^}]*\}", style))
    assert style.index(".n{stroke:none}") >= last_entry
