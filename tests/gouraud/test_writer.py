"""The Gouraud SVG writer: structure, stills vs the animation's values, keyframes, seams, bad input."""

from __future__ import annotations

import json
import re
import struct

import numpy as np
import pytest
from lxml import etree

from converter.encode import gouraudplan, seams
from converter.encode.gradients import exact_gradients
from converter.errors import InputError
from converter.extract import extract, fit_camera
from converter.options import ConversionOptions, Report
from converter.outputs import writer_for
from converter.writers import svg_gouraud
from tests.gouraud.meshes import ellipsoid

SVG = "{http://www.w3.org/2000/svg}"
NUM = re.compile(r"-?\d+(?:\.\d+)?")


@pytest.fixture(scope="module")
def sheet():
    anim = ellipsoid(n_frames=5, subdivisions=2)
    return extract(anim, fit_camera(anim, 128), occlusion=False)


def write(sheet, **kw) -> tuple[etree._Element, bytes, Report]:
    report = Report()
    data = svg_gouraud.write(sheet, ConversionOptions(**kw), report)
    return etree.fromstring(data), data, report


def animated_value(anim: etree._Element, k: int, n_frames: int) -> list[float]:
    """Numbers of a linear <animate> at frame k (t = k / T), interpolated as SMIL does."""
    times = np.array([float(x) for x in anim.get("keyTimes").split(";")])
    vals = [NUM.findall(v) if not v.startswith("#") else [int(v[i:i + 2], 16) for i in (1, 3, 5)]
            for v in anim.get("values").split(";")]
    vals = np.array(vals, float)
    return [float(np.interp(k / n_frames, times, vals[:, c])) for c in range(vals.shape[1])]


def attr_numbers(el: etree._Element, name: str, k: int | None, n_frames: int) -> np.ndarray:
    """An attribute's numbers (colours as 0..255 triples), from its <animate> at frame k when there is one."""
    if k is not None:
        beside = [a for a in el.getparent().findall(f"{SVG}animate") if a.get("href") == f"#{el.get('id')}"]
        for a in el.findall(f"{SVG}animate") + beside:
            if a.get("attributeName") == name:
                return np.array(animated_value(a, k, n_frames))
    v = el.get(name)
    return np.array([int(v[i:i + 2], 16) for i in (1, 3, 5)] if v.startswith("#") else NUM.findall(v), float)


def triangles(root: etree._Element, k: int | None, n_frames: int) -> dict[int, dict[str, np.ndarray]]:
    """Per triangle id: sorted vertex list of its path and its gradient axis and stop colours at frame k."""
    grads = {int(g.get("id")[1:]): g for g in root.iter(f"{SVG}linearGradient")}
    out = {}
    for p in root.iter(f"{SVG}path"):
        if not p.get("fill").startswith("url("):
            continue  # the still's underlay
        f = int(re.search(r"#g(\d+)", p.get("fill")).group(1))
        g = grads[f]
        stops = g.findall(f"{SVG}stop")
        pts = attr_numbers(p, "d", k, n_frames).reshape(3, 2)
        out[f] = {
            "d": pts[np.lexsort(pts.T[::-1])],
            "axis": np.concatenate([attr_numbers(g, a, k, n_frames) for a in ("x1", "y1", "x2", "y2")]),
            "colors": np.concatenate([attr_numbers(s, "stop-color", k, n_frames) for s in stops]),
        }
    return out


def test_registry_picks_this_writer():
    assert writer_for(ConversionOptions(shading="gouraud")) is svg_gouraud.write
    assert writer_for(ConversionOptions(shading="gouraud-chapter")) is svg_gouraud.write


def test_exact_still_structure_and_metadata(sheet):
    root, data, report = write(sheet, shading="gouraud", frame=2)
    paths = [p for p in root.iter(f"{SVG}path") if p.get("fill").startswith("url(")]
    drawn = sheet.order[sheet.visible[2, sheet.order]]
    assert len(paths) == len(drawn)
    # Underneath: one seamless path per part holding every drawn triangle of that part.
    under = [p for p in root.iter(f"{SVG}path") if p.get("fill").startswith("#")]
    parts = np.unique(sheet.part_ids[drawn])
    assert len(under) == len(parts) and list(root.find(f"{SVG}g"))[: len(under)] == under
    assert sum(p.get("d").count("M") for p in under) == len(drawn)
    assert not list(root.iter(f"{SVG}filter")) and not list(root.iter(f"{SVG}animate"))
    for g in root.iter(f"{SVG}linearGradient"):
        assert g.get("gradientUnits") == "userSpaceOnUse" and len(g.findall(f"{SVG}stop")) == 2
    meta = json.loads(root.find(f"{SVG}metadata").text)
    assert root.find(f"{SVG}metadata").get("id") == "facesvg"
    assert meta["shading"] == "gouraud" and meta["gouraud_method"] == "exact"
    # Intensity x one part colour is drawn exactly; only triangles whose vertices carry two part colours are not.
    k = 2
    tri = sheet.faces[sheet.order[sheet.visible[k, sheet.order]]]
    res = exact_gradients(sheet.xy[k][tri].astype(float), sheet.vertex_rgb[k][tri].astype(float)).residual
    base = ellipsoid(1, 2).face_base_colors()[tri]
    one_colour = (np.abs(base - base[:, :1]).max(axis=(1, 2)) == 0)
    assert one_colour.sum() > 0.8 * len(tri) and res[one_colour].max() < 1e-6
    assert report.figures["gouraud_rank1_max_residual"] == pytest.approx(res.max())
    assert data == write(sheet, shading="gouraud", frame=2)[1]  # deterministic


def test_still_gradients_are_the_sheets_vertex_colours(sheet):
    k = 1
    root, _, _ = write(sheet, shading="gouraud", frame=k)
    tris = triangles(root, None, sheet.n_frames)
    ids = np.array(sorted(tris))
    corners = sheet.faces[ids]
    want = exact_gradients(sheet.xy[k][corners].astype(float), sheet.vertex_rgb[k][corners].astype(float))
    axis = np.array([tris[f]["axis"] for f in ids])
    colors = np.array([tris[f]["colors"] for f in ids])
    assert np.abs(axis - np.concatenate([want.start, want.end], axis=1)).max() <= 0.0051
    got_rgb = np.concatenate([want.start_rgb, want.end_rgb], axis=1) * 255
    assert np.abs(colors - got_rgb).max() <= 0.5 + 1e-6


@pytest.mark.parametrize("raw,tol", [(True, 0.006), (False, 0.25)])
def test_animated_values_at_a_frame_equal_that_frames_still(sheet, raw, tol):
    t = sheet.n_frames
    root, _, report = write(sheet, shading="gouraud", raw=raw, tolerance=0.25)
    assert len(list(root.iter(f"{SVG}path"))) == len(sheet.order)
    for k in (0, 2, t - 1):
        still = triangles(write(sheet, shading="gouraud", frame=k)[0], None, t)
        anim = triangles(root, k, t)
        assert set(still) <= set(anim)
        for f, s in still.items():
            assert np.abs(anim[f]["d"] - s["d"]).max() <= tol
            assert np.abs(anim[f]["axis"] - s["axis"]).max() <= tol + 0.01
            assert np.abs(anim[f]["colors"] - s["colors"]).max() <= (1 if raw else 2.5)
    if not raw:
        assert report.counts["gouraud_keys"] < 2 * (t + 1) * len(sheet.order)  # geometry and colour keys


@pytest.mark.parametrize("shading", ["gouraud", "gouraud-chapter"])
def test_gradients_hold_only_stops_and_their_axis_animations_sit_beside_them(sheet, shading):
    """CairoSVG reads every child of a gradient as a stop (black at offset 0): the axis animates from outside."""
    root, _, _ = write(sheet, shading=shading, raw=True)
    grads = list(root.iter(f"{SVG}linearGradient"))
    assert grads and all(c.tag == f"{SVG}stop" for g in grads for c in g)
    ids = {g.get("id") for g in grads}
    targeted = [a for a in root.iter(f"{SVG}animate") if a.get("href")]
    assert {a.get("attributeName") for a in targeted} == {"x1", "y1", "x2", "y2"}
    assert {a.get("href")[1:] for a in targeted} == ids  # every gradient's axis moves (raw: every frame)
    for a in targeted:
        assert a.getprevious() is not None and a.getparent().tag != f"{SVG}linearGradient"


def test_animated_visibility_follows_the_sheet(sheet):
    root, _, _ = write(sheet, shading="gouraud", raw=True)
    assert all(p.get("fill").startswith("url(") for p in root.iter(f"{SVG}path"))  # no underlay when animated
    for p in root.iter(f"{SVG}path"):
        f = int(re.search(r"#g(\d+)", p.get("fill")).group(1))
        vis = sheet.visible[:, f]
        anim = [a for a in p.findall(f"{SVG}animate") if a.get("attributeName") == "display"]
        assert p.get("visibility") is None  # display, which static renderers (Inkscape) honour
        assert (p.get("display") == "none") == (not vis[0])
        if vis.all():
            assert not anim
            continue
        assert anim and anim[0].get("calcMode") == "discrete"
        times = [float(x) for x in anim[0].get("keyTimes").split(";")]
        values = anim[0].get("values").split(";")
        for k in range(sheet.n_frames):
            shown = values[max(i for i, tk in enumerate(times) if tk <= k / sheet.n_frames)]
            assert (shown == "inline") == vis[k]


def test_seam_stroke_is_off_exactly_where_it_would_reach_past_the_outline(sheet):
    """One seam layout for all frames; a stroke is off (stroke-width 0) at the frames seams.stroke_off names."""
    root, _, _ = write(sheet, shading="gouraud", raw=True)
    tris, drawn = sheet.faces[sheet.order], sheet.visible[:, sheet.order]
    corners = seams.welded_ids(sheet.xy, sheet.depth)[tris]
    reach = svg_gouraud.SEAM_STROKE / 2
    skip, _ = seams.skips(corners, drawn, sheet.xy, tris, reach)
    off = seams.stroke_off(corners, drawn, skip, sheet.xy, tris, reach)
    column = {f: j for j, f in enumerate(sheet.order.tolist())}
    seen_off = 0
    for p in root.iter(f"{SVG}path"):
        if p.get("stroke") is None:
            continue
        j = column[int(re.search(r"#g(\d+)", p.get("fill")).group(1))]
        anim = [a for a in p.findall(f"{SVG}animate") if a.get("attributeName") == "stroke-width"]
        if drawn[0, j]:  # static renderers draw frame 0 from the attributes
            assert (p.get("stroke-width") == "0") == off[0, j]
        for k in np.flatnonzero(drawn[:, j]).tolist():
            width = p.get("stroke-width") or str(svg_gouraud.SEAM_STROKE)
            if anim:
                assert anim[0].get("calcMode") == "discrete"
                times = [float(x) for x in anim[0].get("keyTimes").split(";")]
                width = anim[0].get("values").split(";")[max(i for i, t in enumerate(times) if t <= k / sheet.n_frames)]
            assert (float(width) == 0) == off[k, j], (j, k)
            seen_off += int(off[k, j])
    assert seen_off  # this turning ellipsoid has edges that are outline at some frames and interior at others


def test_chapter_still_has_three_ramps_a_filter_and_a_background_per_triangle(sheet):
    root, _, _ = write(sheet, shading="gouraud-chapter", frame=0)
    n = int(sheet.visible[0, sheet.order].sum())
    filters = list(root.iter(f"{SVG}filter"))
    assert len(filters) == n and len(list(root.iter(f"{SVG}linearGradient"))) == 3 * n
    for flt in filters:
        assert flt.get("color-interpolation-filters") == "sRGB"
        ops = [c.tag.replace(SVG, "") for c in flt]
        assert ops == ["feImage", "feImage", "feComposite", "feComposite", "feColorMatrix"]
    for g in root.iter(f"{SVG}linearGradient"):
        a, b = g.findall(f"{SVG}stop")
        assert b.get("stop-opacity") == "0" and a.get("stop-color") == b.get("stop-color")
    drawn = [p for p in root.iter(f"{SVG}path") if p.getparent().tag != f"{SVG}defs"]
    assert len(drawn) == 2 * n  # average-colour background + the filtered triangle
    assert all(p.get("fill").startswith("#") for p in drawn[::2])


def test_chapter_animates_too(sheet):
    root, _, _ = write(sheet, shading="gouraud-chapter", raw=True)
    names = {a.get("attributeName") for a in root.iter(f"{SVG}animate")}
    assert {"d", "x1", "y1", "x2", "y2", "stop-color", "fill"} <= names


def test_seam_layout_strokes_interior_edges_only():
    # A hexagon fan around vertex 0: each triangle has two spokes (interior) and one rim edge (outline).
    fan = np.array([[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)])
    tris = np.concatenate([fan, [[7, 8, 9]]])  # plus a lone triangle: all outline
    outline = gouraudplan.outline_edges(tris)
    assert outline.sum() == 6 + 3
    rotated, closed, stroked = gouraudplan.seam_layout(tris, outline)
    for r, orig in zip(rotated[:6], fan):
        assert sorted(r) == sorted(orig) and list(np.roll(r, -list(r).index(orig[0]))) == list(orig)  # same winding
        assert 0 not in (r[0], r[-1])  # the implicit closing edge (last -> first) is the rim, which is not stroked
    assert not closed[:6].any() and stroked[:6].all()
    assert closed[6] and not stroked[6]  # all outline: left unstroked so the silhouette does not grow


def test_welded_duplicates_share_edges():
    # Two triangles meeting along a seam with duplicated vertices (2==4, 1==5 in every frame).
    xy = np.array([[[0, 0], [10, 0], [0, 10], [10, 10], [0, 10], [10, 0]]], float)
    depth = np.zeros((1, 6))
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    assert gouraudplan.outline_edges(tris).sum() == 6
    ids = seams.welded_ids(xy, depth)
    assert ids[2] == ids[4] and ids[1] == ids[5] and len(set(ids.tolist())) == 4
    assert gouraudplan.outline_edges(tris, ids).sum() == 4


def test_silhouette_edges_tell_folds_from_the_outline():
    # A fold: B begins 0.3 px right of A's right edge without sharing it; all other edges face empty space.
    tri_xy = np.array([[[10, 10], [30, 10], [30, 30]], [[30.3, 10], [50, 10], [30.3, 30]]], float)
    sil = gouraudplan.silhouette_edges(tri_xy, np.ones((2, 3), bool), 64, 64)
    assert sil.tolist() == [[True, False, True], [True, True, False]]
    assert not gouraudplan.silhouette_edges(tri_xy, np.zeros((2, 3), bool), 64, 64).any()  # only outline edges


def test_underlay_stays_inside_the_silhouette_but_covers_folds():
    tri_xy = np.array([[[10, 10], [30, 10], [10, 30]]], float)
    sil = np.array([[True, False, False]])  # only the top edge (y = 10) is silhouette
    (path,) = svg_gouraud.underlay(gouraudplan.underlay(tri_xy, np.full((1, 3, 3), 0.5), np.zeros(1, int), sil))
    pts = np.array(NUM.findall(path.split('"')[1]), float).reshape(3, 2)
    assert np.allclose(pts[:, 1].min(), 10 + gouraudplan.UNDERLAY_INSET, atol=0.06)  # top edge pulled in
    assert np.allclose(pts[:, 0].min(), 10, atol=0.06)  # left edge (not silhouette) kept
    assert 'fill="#80' in path


def test_exact_still_strokes_only_interior_edges(sheet):
    root, _, _ = write(sheet, shading="gouraud", frame=0)
    paths = [p for p in root.iter(f"{SVG}path") if p.get("fill").startswith("url(")]
    open_paths = [p for p in paths if not p.get("d").endswith("Z")]
    assert open_paths and all(p.get("stroke") for p in open_paths)
    assert root.find(f"{SVG}g").get("stroke-width") == str(svg_gouraud.SEAM_STROKE)


def test_frame_out_of_range_is_one_clear_error(sheet):
    with pytest.raises(InputError, match="frame 99"):
        svg_gouraud.write(sheet, ConversionOptions(shading="gouraud", frame=99), Report())
    with pytest.raises(InputError):
        svg_gouraud.write(sheet, ConversionOptions(shading="gouraud-chapter", frame=-1), Report())


def test_cli_writes_a_gouraud_still_and_refuses_a_bad_frame(tmp_path, capsys):
    from converter import cli

    anim = ellipsoid(n_frames=2, subdivisions=1)
    src = tmp_path / "egg.obj"
    src.write_text("\n".join([f"v {x} {y} {z}" for x, y, z in anim.frames[0]]
                             + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in anim.faces]) + "\n")
    cache = tmp_path / "egg.pc2"
    header = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, anim.n_vertices, 0.0, 1.0, anim.n_frames)
    cache.write_bytes(header + anim.frames.astype("<f4").tobytes())
    out = tmp_path / "egg.svg"
    common = ["--cache", str(cache), "--shading", "gouraud", "--size", "64", "--no-occlusion"]
    assert cli.main(["convert", str(src), "-o", str(out), "--frame", "1", *common]) == 0
    root = etree.fromstring(out.read_bytes())
    assert list(root.iter(f"{SVG}linearGradient"))
    bad = tmp_path / "bad.svg"
    assert cli.main(["convert", str(src), "-o", str(bad), "--frame", "5", *common]) == 2
    assert not bad.exists()
    assert "frame 5" in capsys.readouterr().err


@pytest.mark.parametrize("shading", ["gouraud", "gouraud-chapter"])
def test_edge_cases_nothing_drawn_and_single_frame(sheet, shading):
    import dataclasses

    empty = dataclasses.replace(sheet, order=np.zeros(0, np.int32))
    for kw in ({"frame": 1}, {}, {"raw": True}):
        root = etree.fromstring(svg_gouraud.write(empty, ConversionOptions(shading=shading, **kw), Report()))
        assert not list(root.iter(f"{SVG}path")) and root.find(f"{SVG}metadata") is not None
    one = dataclasses.replace(sheet, xy=sheet.xy[:1], depth=sheet.depth[:1], visible=sheet.visible[:1],
                              face_rgb=sheet.face_rgb[:1], vertex_rgb=sheet.vertex_rgb[:1])
    root = etree.fromstring(svg_gouraud.write(one, ConversionOptions(shading=shading), Report()))
    shown = [p for p in root.iter(f"{SVG}path") if p.get("filter") or p.get("stroke") or
             (p.get("fill", "").startswith("url(") and shading == "gouraud")]
    assert len(shown) == int(sheet.visible[0, sheet.order].sum())  # triangles never shown are left out
    assert not list(root.iter(f"{SVG}animate"))  # one frame: nothing moves
