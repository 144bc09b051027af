"""Degenerate motion through the encoder and every writer: parts scaled to zero, collapsed to a line or a point,
turned away or moved behind the camera, whole frames hidden, coincident vertices, duplicate and zero-area
triangles. Every conversion either succeeds with finite numbers everywhere in its output and report, or stops
with one InputError; any other exception is a bug (a user would see a traceback)."""

from __future__ import annotations

import html
import io
import json
import re
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from converter.animation import DEFAULT_PART_COLORS, FaceAnimation, Part
from converter.convert import convert_animation
from converter.encode import groups
from converter.errors import InputError
from converter.options import ConversionOptions, Report
from converter.outputs import OUTPUTS
from converter.writers import player

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "fap2d"))  # the fap2d tests' synthetic face and its feature points

from standin import synthetic_face  # noqa: E402

PART_NAMES = ("skin", "eye", "teeth")
EVENTS = ("zero", "line", "point_z", "away", "toward", "coincident", "huge", "tiny")
# A number as SVG, the player's JSON or the report spell it; and the words a non-finite float is printed as.
NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
HEX_COLOR = re.compile(rb"#[0-9a-fA-F]{3,8}\b")  # not numbers (#2e8888 would read as 2e8888)
NON_FINITE = re.compile(rb"(?<![A-Za-z_])(?:nan|-?inf(?:inity)?)(?![A-Za-z_])", re.I)
JSON_SCRIPT = re.compile(rb'<script[^>]*type="application/json"[^>]*>(.*?)</script>', re.S)
CHEAP = settings(max_examples=30, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.too_slow])
FEW = settings(CHEAP, max_examples=12)


def grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid over [-1, 1]^2 at z = 0, counter-clockwise seen from +z (the camera's side)."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    verts = np.stack([u, v, np.zeros_like(u)], -1).reshape(-1, 3)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).reshape(-1)
    faces = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return verts, faces


@st.composite
def degenerate_animations(draw) -> FaceAnimation:
    """A few grid parts moving rigidly with jitter, with degenerate events in some frames and degenerate
    triangles in the topology."""
    n_parts = draw(st.integers(1, 3))
    t = draw(st.integers(1, 30))  # 1: a still mesh
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    verts, faces, part_ids, ranges = [], [], [], []
    at = 0
    for p in range(n_parts):
        v, f = grid(draw(st.integers(2, 9)))  # 9: 128 triangles, enough for a band of its own
        size = 1.0 if p == 0 else 0.35
        v = v * size + np.array([0.0, 0.0, 0.0] if p == 0 else [0.5 * p - 0.8, 0.4, 0.05 * p])
        verts.append(v)
        faces.append(f + at)
        part_ids.append(np.full(len(f), p))
        ranges.append(np.arange(at, at + len(v)))
        at += len(v)
    base = np.concatenate(verts)
    faces_ = np.concatenate(faces)
    part_ids_ = np.concatenate(part_ids)
    # Rigid sway with jitter per part (rotation about z, scale, translation), then the degenerate events.
    frames = np.repeat(base[None], t, 0)
    for p, idx in enumerate(ranges):
        angle = 0.3 * np.sin(np.linspace(0, 2 * np.pi, t)) + 0.01 * rng.standard_normal(t)
        scale = 1.0 + 0.1 * np.sin(np.linspace(0, np.pi, t)) * p
        shift = 0.05 * rng.standard_normal((t, 3))
        c, s = np.cos(angle), np.sin(angle)
        centre = base[idx].mean(axis=0)
        rel = base[idx] - centre
        x = c[:, None] * rel[None, :, 0] - s[:, None] * rel[None, :, 1]
        y = s[:, None] * rel[None, :, 0] + c[:, None] * rel[None, :, 1]
        frames[:, idx, 0] = centre[0] + scale[:, None] * x + shift[:, None, 0]
        frames[:, idx, 1] = centre[1] + scale[:, None] * y + shift[:, None, 1]
        frames[:, idx, 2] = base[idx, 2][None] + shift[:, None, 2]
    events = draw(st.lists(st.tuples(st.sampled_from(EVENTS), st.integers(-1, n_parts - 1),
                                     st.sets(st.integers(0, t - 1), min_size=1)), max_size=4))
    for kind, p, when in events:
        idx = np.arange(len(base)) if p < 0 else ranges[p]  # -1: every part at once
        k = np.array(sorted(when))[:, None]
        pts = frames[k, idx]
        centre = pts.mean(axis=1, keepdims=True)
        if kind == "zero":  # scaled to zero: every vertex on one point
            pts = np.broadcast_to(centre, pts.shape)
        elif kind == "line":  # collapsed to a line along x
            pts = np.concatenate([pts[..., :1], np.broadcast_to(centre[..., 1:], pts[..., 1:].shape)], -1)
        elif kind == "point_z":  # flattened along the view axis onto its edge: a line on screen
            pts = np.concatenate([np.broadcast_to(centre[..., :1], pts[..., :1].shape), pts[..., 1:]], -1)
        elif kind == "away":  # mirrored: every triangle faces away (hidden)
            pts = np.concatenate([2 * centre[..., :1] - pts[..., :1], pts[..., 1:]], -1)
        elif kind == "toward":  # far toward the camera: behind it when the camera frames another part
            pts = pts + np.array([0.0, 0.0, 40.0])
        elif kind == "coincident":  # every other vertex onto its neighbour
            pts = pts.copy()
            pts[:, 1::2] = pts[:, 0:-1:2][:, :pts[:, 1::2].shape[1]]
        elif kind == "huge":
            pts = centre + (pts - centre) * 1e6
        else:  # tiny: a hair short of zero
            pts = centre + (pts - centre) * 1e-7
        frames[k, idx] = pts
    extra = []
    if draw(st.booleans()):  # duplicate triangles
        extra.append(faces_[: draw(st.integers(1, 4))])
    if draw(st.booleans()):  # zero-area triangles: a repeated corner, and three collinear grid vertices
        extra.append(np.array([[0, 0, 1], [0, 1, 2]]))
    if extra:
        more = np.concatenate(extra)
        faces_ = np.concatenate([faces_, more])
        part_ids_ = np.concatenate([part_ids_, np.zeros(len(more), np.int64)])  # vertices of part 0
    parts = tuple(Part(n, DEFAULT_PART_COLORS[n]) for n in PART_NAMES[:n_parts])
    return FaceAnimation(frames.astype(np.float32), faces_, part_ids_, parts, 25.0, "degenerate")


def assert_finite_output(data: bytes, report: Report, kind: str) -> None:
    """Every number in the output and the report is finite: strict JSON, no NaN or Infinity spelled anywhere."""
    json.dumps(report.to_json(), allow_nan=False)
    json.loads(report.dumps())
    if kind == "player":  # its keys, decoded as the verifier reads them
        decoded = player.decode(data)
        strict_json(json.dumps(decoded.meta))
        shown_xy = decoded.path_xy()[decoded.shown]  # a vertex no shown path uses has no keys (NaN)
        assert np.isfinite(shown_xy).all()
    if data[:2] == b"PK":  # a package: its JSON members
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            for name in z.namelist():
                if name.endswith(".json"):
                    strict_json(z.read(name).decode())
    elif b"<svg" in data[:200]:
        assert not NON_FINITE.search(data), NON_FINITE.search(data)
        meta = re.search(rb'<metadata id="facesvg">(.*?)</metadata>', data, re.S)
        assert meta is not None
        strict_json(html.unescape(meta.group(1).decode()))
        numbers = np.array([float(x) for x in NUMBER.findall(HEX_COLOR.sub(b"", data))])
        assert np.isfinite(numbers).all()
    else:  # an HTML page: its JSON blocks (the script itself may well say Infinity)
        for block in JSON_SCRIPT.findall(data):
            strict_json(html.unescape(block.decode()) if b"&quot;" in block else block.decode())


def strict_json(text: str) -> None:
    """Parse text as JSON that holds no NaN or Infinity."""
    def refuse(name):
        raise AssertionError(f"non-finite {name} in JSON")

    json.loads(text, parse_constant=refuse)


def convert_or_input_error(anim: FaceAnimation, **options) -> None:
    """Convert; an InputError is an answer, any other exception fails the test; success must be finite."""
    opts = ConversionOptions.given(size=64, **options)
    try:
        result = convert_animation(anim, opts)
    except InputError as exc:
        assert str(exc).strip(), "an InputError says what is wrong"
        event(f"InputError: {str(exc)[:40]}")
        return
    event("converted")
    assert_finite_output(result.data, result.report, opts.to)


# Every registered kind (those whose 2D stage needs more than a mesh, e.g. a FAP stream, answer InputError here;
# test_fap2d_on_a_degenerate_neutral_face gives fap2d its stream) in both shadings.
CONFIGS = [pytest.param(dict(to=k, shading=s), id=f"{k}-{s}") for k in OUTPUTS for s in ("flat", "gouraud")]


@pytest.mark.parametrize("options", CONFIGS)
@CHEAP
@given(anim=degenerate_animations(), frame_on=st.sampled_from([None, "skin"]))
def test_every_output_and_shading(anim, frame_on, options):
    convert_or_input_error(anim, frame_on=frame_on, **options)


@pytest.mark.parametrize("shading", ["flat", "gouraud"])
@FEW
@given(anim=degenerate_animations())
def test_still_of_frame_0(anim, shading):
    convert_or_input_error(anim, frame=0, shading=shading)


@pytest.mark.slow
@pytest.mark.parametrize("options", [dict(preset="mobile"), dict(max_triangles=6), dict(preset="mobile", to="player"),
                                     dict(shading="gouraud-chapter")],
                         ids=["mobile", "max_triangles", "mobile-player", "gouraud-chapter"])
@FEW
@given(anim=degenerate_animations())
def test_triangle_budget_and_chapter_shading(anim, options):
    convert_or_input_error(anim, **options)


def test_fap2d_without_a_stream_is_an_input_error():
    anim = grid_animation()
    with pytest.raises(InputError, match="FAP stream"):
        convert_animation(anim, ConversionOptions(to="fap2d", size=64))


def grid_animation() -> FaceAnimation:
    """One still grid part."""
    v, f = grid(3)
    return FaceAnimation(v[None].astype(np.float32), f, np.zeros(len(f)), (Part("skin", (0.8, 0.6, 0.5)),), 25.0)


@pytest.fixture(scope="module")
def fap2d_face(tmp_path_factory):
    """The fap2d tests' synthetic face, its FDP written as JSON, and Xface's joy.fap."""
    anim, fdp = synthetic_face(17)
    path = tmp_path_factory.mktemp("fdp") / "face.fdp.json"
    path.write_text(json.dumps({"points": fdp.points, "parts": fdp.parts, "fapu": fdp.fapu}))
    return anim, path, ROOT / "tests" / "data" / "mpeg4" / "xface" / "joy.fap"


@pytest.mark.slow
@settings(FEW, max_examples=8)
@given(kind=st.sampled_from(("zero", "line", "away", "coincident")), part=st.integers(0, 2))
def test_fap2d_on_a_degenerate_neutral_face(fap2d_face, kind, part):
    anim, fdp, fap = fap2d_face
    frame = anim.frames[0].astype(np.float64).copy()
    idx = np.unique(anim.faces[anim.part_ids == part])
    centre = frame[idx].mean(axis=0)
    if kind == "zero":
        frame[idx] = centre
    elif kind == "line":
        frame[idx, 1:] = centre[1:]
    elif kind == "away":
        frame[idx, 0] = 2 * centre[0] - frame[idx, 0]
    else:
        frame[idx[1::2]] = frame[idx[0:-1:2]][: len(idx[1::2])]
    convert_or_input_error(anim.with_frames(frame[None]), to="fap2d", fap=str(fap), fdp=str(fdp))


# --- the rigid planner on singular frames, directly ---------------------------------------------------------------
def test_invertible_refuses_singular_and_collapsed_frames():
    mats = np.zeros((4, 2, 3))
    mats[:, 0, 0] = mats[:, 1, 1] = 1.0
    assert groups.invertible(mats)
    zero, line, nan = mats.copy(), mats.copy(), mats.copy()
    zero[2, :, :2] = 0.0  # scaled to zero in frame 2
    line[1, 1, 1] = groups.MIN_SCALE / 2  # collapsed (nearly) to a line in frame 1
    nan[3, 0, 2] = np.nan
    for m in (zero, line, nan):
        assert not groups.invertible(m)
    rot = mats.copy()
    rot[:, :, :2] = [[0.0, -groups.MIN_SCALE * 2], [groups.MIN_SCALE * 2, 0.0]]  # small but round: invertible
    assert groups.invertible(rot)


def test_local_tracks_refuses_a_singular_frame_and_inverts_the_others():
    rng = np.random.default_rng(1)
    mats = np.zeros((3, 2, 3))
    mats[:, :, :2] = [[2.0, 0.5], [0.0, 1.5]]
    mats[:, :, 2] = [10.0, -4.0]
    pts = rng.normal(size=(3, 5, 3, 2))
    local = groups.local_tracks(pts, mats)
    back = groups.apply_linear(mats[:, :, :2], local) + mats[:, None, None, :, 2]
    np.testing.assert_allclose(back, pts, atol=1e-12)
    mats[1, :, :2] = 0.0
    with pytest.raises(ValueError, match="degenerate"):
        groups.local_tracks(pts, mats)


def band_sheet(t: int = 24, collapse: str = "band") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """xy (T, V, 2) px of a big swaying sheet (the head) and a smaller one (its own band) swaying otherwise, with
    faces and part ids; in frames 4-6 the small one (collapse 'band') or the big one ('head') collapses to a point."""
    rng = np.random.default_rng(5)
    k = np.arange(t)

    def sway(v, radius, centre, turn, phase):
        a = turn * np.sin(2 * np.pi * k / t + phase) + 0.002 * rng.standard_normal(t)
        c, s = np.cos(a)[:, None], np.sin(a)[:, None]
        x, y = v[None, :, 0] * radius, v[None, :, 1] * radius
        return np.stack([c * x - s * y, s * x + c * y], -1) + centre + rng.normal(0, 0.05, (t, 1, 2))

    v0, f0 = grid(12)
    v1, f1 = grid(9)
    xy = np.concatenate([sway(v0, 120, [256, 256], 0.3, 0.0), sway(v1, 40, [300, 140], 0.8, 1.0)], axis=1)
    faces = np.concatenate([f0, f1 + len(v0)])
    part_ids = np.r_[np.zeros(len(f0), np.int64), np.ones(len(f1), np.int64)]
    sel = np.arange(len(v0), len(v0) + len(v1)) if collapse == "band" else np.arange(len(v0))
    xy[4:7, sel] = xy[4:7, sel].mean(axis=1, keepdims=True)
    return xy.astype(np.float32), faces, part_ids


@pytest.mark.parametrize("collapse", ["band", "head"])
def test_plan_keys_a_collapsed_group_plainly(collapse):
    from converter.encode.budget import ErrorBudget

    xy, faces, part_ids = band_sheet(collapse=collapse)
    tris = np.arange(len(faces))
    active = np.ones((xy.shape[0], len(faces)), bool)
    budget = ErrorBudget.split(0.25, 512)
    costs = groups.Costs(lambda m: 40 + 30 * len(m.anims), 4, 3.0)
    plan = groups.plan(xy, faces, part_ids, 0, tris, active, budget, costs, head_clusters=1)
    if plan.head is not None:
        assert groups.invertible(plan.head.matrices)
        for b in np.unique(plan.band[plan.band >= 0]).tolist():  # only sound bands are wrapped
            assert groups.invertible(plan.motions[b].matrices)
        if collapse == "head":
            assert not plan.head.anims  # no head transform: the identity
        local = plan.track.take(slice(0, len(tris)))
        played = groups.compose_tracks(plan, local)
        exact = xy[:, faces[tris[plan.order]]].reshape(xy.shape[0], len(tris), 6)
        assert np.isfinite(played).all()
        assert np.abs(played - exact).max() < 1e-3  # the tracks (before keyframing) compose back exactly
    for m in plan.motions:
        assert np.isfinite(m.matrices).all()


# --- the overlap search with a path blown up on screen ------------------------------------------------------------
def random_paths(seed: int, big_share: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """xy (T, P, 3, 2) of small triangles drifting about, a share of them 30x larger; active (T, P); bands (P,)."""
    rng = np.random.default_rng(seed)
    t, p = int(rng.integers(1, 6)), int(rng.integers(2, 300))
    centre = rng.uniform(0, 200, (1, p, 1, 2)) + rng.normal(0, 1, (t, 1, 1, 2)).cumsum(0)
    size = np.where(rng.random(p) < big_share, 90.0, 3.0)[None, :, None, None]
    xy = (centre + rng.normal(0, 1, (t, p, 3, 2)) * size).astype(np.float32)
    return xy, rng.random((t, p)) < 0.8, rng.integers(0, 3, p)


@pytest.mark.parametrize("seed", range(8))
def test_big_boxes_tested_directly_find_the_grids_pairs(seed, monkeypatch):
    from converter.encode import overlap

    xy, active, band = random_paths(seed)
    for bands in (None, band):
        for margin in (overlap.STROKE_MARGIN_PX, -0.2):
            grid_pairs = overlap.overlap_pairs(xy, active, band=bands, margin=margin)
            with monkeypatch.context() as m:
                m.setattr(overlap, "BIG_CELLS", 4)  # most boxes "big": found by the direct test
                direct = overlap.overlap_pairs(xy, active, band=bands, margin=margin)
            np.testing.assert_array_equal(direct, grid_pairs)


def test_a_path_blown_up_across_the_screen_is_searched_without_a_cell_per_pixel():
    from converter.encode import overlap

    xy, active, _ = random_paths(3, big_share=0.0)
    xy += 100  # all inside the first quadrant
    xy[:, 0] = [[0, 0], [4e9, 0], [0, 4e9]]  # a vertex near the eye plane: billions of px (of 2 px cells)
    pairs = overlap.overlap_pairs(xy, active)
    shown = active[:, 0]
    partners = np.unique(pairs[pairs[:, 0] == 0, 1])
    # every path drawn in a frame with path 0 lies inside its triangle there: all of them are its partners
    expected = np.flatnonzero((active & shown[:, None]).any(axis=0))
    np.testing.assert_array_equal(partners, expected[expected > 0])


# --- figures and inputs --------------------------------------------------------------------------------------------
def test_report_json_leaves_out_figures_that_could_not_be_computed():
    report = Report(figures={"a": float("nan"), "b": float("inf"), "c": 1.23456789, "d": 2},
                    timings={"t": float("nan"), "u": 0.5})
    data = report.to_json()
    assert data["figures"] == {"c": 1.2346, "d": 2} and data["timings"] == {"u": 0.5}
    strict_json(report.dumps())


def test_simplify_deviation_is_finite_on_a_collapsed_neutral_frame():
    from converter import simplify

    sys.path.insert(0, str(ROOT / "tests" / "rigid"))
    from synth import captured_head

    head = captured_head(8)
    eye = np.unique(head.faces[head.part_ids == 1])
    frames = head.frames.copy()
    frames[0, eye] = frames[0, eye].mean(axis=0)  # the eye collapsed to a point in the frame it is attached at
    report = Report()
    simplify.simplify(head.with_frames(frames), 100, report, options=ConversionOptions(size=128))
    figures = {k: v for k, v in report.figures.items() if k.startswith("budget_deviation")}
    assert "budget_deviation_mean_px" in figures and np.isfinite(list(figures.values())).all(), figures
    # the eye's vertices hang on its collapsed triangles and so do not follow it as it opens: measured, not NaN
    assert figures["budget_deviation_px_eye"] > 1.0


def test_barycentric_falls_back_on_the_longest_edge_of_a_degenerate_triangle():
    from trimesh.triangles import points_to_barycentric

    from converter.simplify import barycentric

    tris = np.array([[[0, 0, 0], [2, 0, 0], [1, 0, 0]],  # collinear
                     [[1, 1, 1], [1, 1, 1], [1, 1, 1]],  # one point
                     [[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)  # a proper triangle: trimesh's answer
    pts = np.array([[0.5, 0, 0], [1, 1, 1], [0.2, 0.3, 0]])
    bary = barycentric(tris, pts, points_to_barycentric)
    assert np.isfinite(bary).all()
    np.testing.assert_allclose(bary.sum(axis=1), 1.0)
    np.testing.assert_allclose(np.einsum("nk,nkj->nj", bary, tris), pts, atol=1e-12)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e30"])
def test_bad_positions_are_refused_at_load_naming_the_file(tmp_path, value):
    from converter import formats

    path = tmp_path / "broken_face.obj"
    path.write_text(f"v 0 0 0\nv 1 0 0\nv {value} 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"^broken_face\.obj: vertex 2 of frame 0 has ") as err:
        formats.load(path)
    assert ("NaN or infinite" in str(err.value)) == (value != "1e30")


def test_a_nan_joint_track_is_refused_at_load_naming_the_file(tmp_path):
    from converter import formats
    from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder

    b = GltfBuilder("tests")
    v, f = grid(3)
    pos = b.accessor(v.astype(np.float32), minmax=True, target=ARRAY_BUFFER)
    ind = b.accessor(f.reshape(-1).astype(np.uint16), target=ELEMENT_ARRAY_BUFFER)
    mesh = b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "indices": ind}]})
    node = b.add("nodes", {"mesh": mesh})
    b.add("scenes", {"nodes": [node]})
    times = b.accessor(np.float32([[0], [1], [2]]), minmax=True)
    scale = b.accessor(np.float32([[1, 1, 1], [1, np.nan, 1], [1, 1, 1]]))
    b.add("animations", {"samplers": [{"input": times, "output": scale}],
                         "channels": [{"sampler": 0, "target": {"node": node, "path": "scale"}}]})
    path = tmp_path / "nan_scale.glb"
    path.write_bytes(b.glb())
    with pytest.raises(InputError, match=r"nan_scale\.glb.*NaN or infinite"):
        formats.load(path)
