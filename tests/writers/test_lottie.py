"""The Lottie writer (converter.writers.lottie): structure, determinism, the round trip through its reader against
the SVG's evaluation and the exact projection, the dotLottie package, and what it refuses."""

import io
import json
import zipfile

import numpy as np
import pytest

from converter import verify
from converter.convert import extract_sheet, load, prepare
from converter.encode import flatplan, groups
from converter.errors import InputError
from converter.options import ConversionOptions, Report
from converter.outputs import OUTPUTS
from converter.writers import lottie, svg_anim
from tests.reference import lottie as reference
from tests.rigid.synth import captured_head


@pytest.fixture(scope="module")
def sample(sample_path):
    """The bundled face (default options): its prepared animation and Sheet."""
    options = ConversionOptions()
    anim = prepare(load(str(sample_path), options), options, Report())
    return anim, extract_sheet(anim, options, Report())


@pytest.fixture(scope="module")
def sample_lottie(sample):
    report = Report()
    return lottie.write(sample[1], ConversionOptions(), report), report


@pytest.fixture(scope="module")
def head():
    """A captured-like head whose plan has rigid groups (head and bands), with its Lottie and SVG."""
    options = ConversionOptions(size=192, occlusion=False)
    anim = captured_head()
    sheet = extract_sheet(anim, options, Report())
    report = Report()
    return anim, sheet, lottie.write(sheet, options, report), report


def _plan(sheet, options=None):
    """The plan the Lottie writer spells (same costs)."""
    options = options or ConversionOptions()
    t = sheet.n_frames
    return flatplan.plan(sheet, options, "bounded",
                         groups.Costs(lambda m: len(lottie._group_open(m, t)), len(lottie.GROUP_CLOSE),
                                      lottie.BYTES_PER_KEY))


def _elements(doc):
    """Element groups (those holding paths) of the document, in list order (top first), depth first."""
    out = []

    def walk(items):
        for it in items:
            if it["ty"] == "gr":
                if any(x["ty"] == "sh" for x in it["it"]):
                    out.append(it)
                else:
                    walk(it["it"])

    for layer in doc["layers"]:
        walk(layer["shapes"])
    return out


def test_structure_follows_the_plan(sample, sample_lottie):
    data, report = sample_lottie
    doc = json.loads(data)
    fp = _plan(sample[1])
    assert doc["fr"] == sample[1].fps and doc["op"] == sample[1].n_frames and doc["ip"] == 0
    assert (doc["w"], doc["h"]) == (sample[1].camera.width, sample[1].camera.height)
    els = _elements(doc)[::-1]  # back to front: Lottie lists the top first
    starts = fp.starts
    assert len(els) == len(starts) - 1 == report.counts["paths"]
    bare = fp.strokes.bare(fp.tris)
    n_sets = 0
    for el, a, b in zip(els, starts[:-1].tolist(), starts[1:].tolist()):
        kinds = [x["ty"] for x in el["it"]]
        assert kinds.count("sh") == b - a and kinds.count("fl") == 1
        assert ("st" in kinds) == (not bare[a]), (a, kinds)
        assert kinds[-1] == "tr"  # lottie-web draws a group only with its transform, last
        if b - a > 1:
            n_sets += 1
            assert kinds.count("st") == 1  # a merged element is one fill and one stroke
    assert n_sets == len(fp.sets) > 0
    assert doc["meta"]["facesvg"]["triangle_order"] == fp.tris.tolist()


def test_draw_order_is_reversed():
    """Two overlapping triangles: the one drawn last in the SVG (in front) is listed first in Lottie."""
    data, doc_order = _two_triangles()
    doc = json.loads(data)
    listed = doc["meta"]["facesvg"]["triangle_order"]
    assert listed == doc_order
    els = _elements(doc)
    assert len(els) == 2
    # the top element (listed first) is the last triangle of the document order: its fill colour is the front one's
    front = lottie.decode(data)
    assert front.triangles.tolist() == listed
    top_colour = els[0]["it"][-2]["c"]["k"]
    assert np.allclose(np.array(top_colour) * 255, front.rgb[0, -1], atol=0.6)
    assert not np.allclose(front.rgb[0, 0], front.rgb[0, -1], atol=3)


def _two_triangles():
    from converter.animation import FaceAnimation, Part

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0.3], [1.2, 0.2, 0.3], [0.2, 1.2, 0.3]], np.float32)
    frames = np.repeat(v[None], 4, axis=0)
    frames[:, 3:, 0] += np.linspace(0, 0.1, 4)[:, None]
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    anim = FaceAnimation(frames, faces, np.array([0, 1]), (Part("a", (0.9, 0.2, 0.2)), Part("b", (0.2, 0.2, 0.9))),
                         10.0, "two")
    options = ConversionOptions(size=64, occlusion=False)
    sheet = extract_sheet(anim, options, Report())
    fp = _plan(sheet, options)
    return lottie.write(sheet, options, Report()), fp.tris.tolist()


def test_deterministic(sample, sample_lottie):
    again = lottie.write(sample[1], ConversionOptions(), Report())
    assert again == sample_lottie[0]
    assert lottie.package(again) == lottie.package(sample_lottie[0])


def test_round_trip_matches_the_svg_and_the_exact_projection(sample, sample_lottie):
    anim, sheet = sample
    data = sample_lottie[0]
    svg = svg_anim.write(sheet, ConversionOptions(), Report())
    mine, theirs = lottie.decode(data), verify.evaluate(svg)
    assert mine.triangles.tolist() == theirs.triangles.tolist()  # the same plan: same paths, same order
    assert (mine.shown == theirs.shown).all() and (mine.collapsed == theirs.collapsed).all()
    scale = json.loads(data)["meta"]["facesvg"]["encoding"]["scale"]
    gap = np.abs(mine.xy - theirs.xy).max(axis=(2, 3))[mine.shown]
    # The SVG rounds keyTimes (within its budget); Lottie keys sit on exact half frames: the two differ only on
    # segments whose keyTime the SVG rounded.
    assert np.mean(gap <= 1.0 / scale) > 0.995 and gap.max() < 2 * 0.25
    v = verify.verify_animation(data, anim)
    assert v.ok and v.max_px <= 0.25 and v.visibility_mismatches == 0, v.summary()
    # colours: every shown path's fill within the colour tolerance of the exact shade
    exact = sheet.face_rgb[:, sheet.color_columns(mine.triangles)] * 255
    err = np.abs(mine.rgb - exact).max(axis=2)[mine.shown]
    assert err.max() <= ConversionOptions().color_tolerance + 1.0


def test_round_trip_equals_the_plans_keys(head):
    """The reader gives back the plan's keys exactly (integer grid, group matrices) at every frame: decode is
    checked against an evaluation of the plan that shares no code with it."""
    anim, sheet, data, report = head
    assert report.counts.get("rigid_groups", 0) >= 1
    fp = _plan(sheet, ConversionOptions(size=192, occlusion=False))
    assert fp.rigid is not None
    d = lottie.decode(data)
    t = sheet.n_frames
    tl, scale = fp.timeline, fp.budget.scale
    local = np.zeros((t, fp.n_paths, 6))
    frames = np.arange(t)
    for j in range(fp.n_paths):
        sel = tl.path == j
        if not sel.any():
            continue
        rows = np.rint(tl.values[sel].astype(np.float64) * scale) / scale
        for c in range(6):
            local[:, j, c] = np.interp(frames, tl.half[sel] / 2, rows[:, c])
    inside = flatplan.merged_paths(fp.sets)
    for band in fp.merged:
        for row, k in enumerate(band.sets.tolist()):
            a, b = fp.sets[k]
            sel = band.timeline.path == row
            rows = np.rint(band.timeline.values[sel].astype(np.float64) * scale) / scale
            for i in range(b - a):
                for c in range(6):
                    local[:, a + i, c] = np.interp(frames, band.timeline.half[sel] / 2, rows[:, 6 * i + c])
    want = groups.compose_tracks(fp.rigid, local).reshape(t, -1, 3, 2)
    assert len(inside) and d.triangles.tolist() == fp.tris.tolist()
    assert np.abs(d.xy - want).max() < 1e-6
    v = verify.verify_animation(data, anim)
    assert v.ok, v.summary()


def test_a_perturbed_key_fails_verification(head):
    anim, _, data, _ = head
    doc = json.loads(data)
    el = _elements(doc)[len(_elements(doc)) // 2]
    sh = next(x for x in el["it"] if x["ty"] == "sh")
    keys = sh["ks"]["k"] if sh["ks"]["a"] else None
    value = keys[len(keys) // 2]["s"][0] if keys else sh["ks"]["k"]
    value["v"][1][0] += 12  # one vertex of one key: a pixel off under the layer's 1/scale
    bad = json.dumps(doc).encode()
    assert verify.verify_animation(data, anim).ok
    v = verify.verify_animation(bad, anim)
    assert not v.ok and v.max_px > 0.5


def test_dotlottie_package(sample, sample_lottie):
    report = Report()
    data = lottie.write_dotlottie(sample[1], ConversionOptions(), report)
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        assert z.namelist() == ["manifest.json", "animations/face.json"]
        manifest = json.loads(z.read("manifest.json"))
        assert manifest["animations"][0]["id"] == "face" and manifest["version"]
        assert z.read("animations/face.json") == sample_lottie[0]
        assert all(i.date_time == lottie.ZIP_DATE and i.compress_type == zipfile.ZIP_DEFLATED for i in z.infolist())
    assert reference.animation_of(data)[0] == json.loads(sample_lottie[0])  # as the reference players read it
    assert lottie.decode(data).triangles.tolist() == lottie.decode(sample_lottie[0]).triangles.tolist()
    assert len(data) < 0.2 * len(sample_lottie[0])


@pytest.mark.parametrize("options, message", [
    (dict(shading="gouraud"), "flat-shaded only"),
    (dict(shading="gouraud-chapter"), "flat-shaded only"),
    (dict(raw=True), "--raw"),
])
def test_what_lottie_cannot_do_is_an_input_error(options, message):
    anim = captured_head(n_frames=4, n=4)
    for kind in ("lottie", "dotlottie"):
        opts = ConversionOptions(to=kind, size=64, occlusion=False, **options)
        with pytest.raises(InputError, match=message):
            OUTPUTS[kind].writer_for(opts)(extract_sheet(anim, opts, Report()), opts, Report(), lambda s, f: None)


def test_a_still_is_one_frame(sample):
    anim, sheet = sample
    options = ConversionOptions(frame=7)
    data = lottie.write(sheet, options, Report())
    doc = json.loads(data)
    assert doc["op"] == 1 and doc["meta"]["facesvg"]["encoding"] == {"mode": "still", "scale": 12, "frame": 7}
    v = verify.verify_animation(data, anim)
    assert v.ok and v.frames == 1, v.summary()


def test_reader_refuses_what_is_not_facesvg_lottie():
    with pytest.raises(InputError, match="not valid JSON"):
        lottie.decode(b"{nope")
    with pytest.raises(InputError, match="no layers"):
        lottie.decode(b"{}")
    with pytest.raises(InputError, match="meta.facesvg"):
        lottie.decode(b'{"layers": []}')
    with pytest.raises(InputError, match="dotLottie"):
        lottie.decode(b"PK\x03\x04garbage")


def test_schema_valid(sample_lottie, head):
    reference.require()
    assert reference.schema_errors(json.loads(sample_lottie[0]), strict=True) == []
    assert reference.schema_errors(json.loads(head[2]), strict=True) == []


def test_evaluate_keys_holds_and_interpolates():
    times, values = np.array([0.0, 4.0, 6.0]), np.array([[0.0], [8.0], [10.0]])
    got = lottie.evaluate_keys(times, values, np.array([False, True, False]), np.arange(8.0))[:, 0]
    assert got.tolist() == [0, 2, 4, 6, 8, 8, 10, 10]  # linear, then held until the next key, then the last


def test_fixed_numbers():
    assert lottie.fixed(np.array([0, 5, -5, 120, -49973]), 4) == ["0", "0.0005", "-0.0005", "0.012", "-4.9973"]
    assert lottie.fixed(np.array([3, -2]), -2) == ["300", "-200"]



def test_a_lottie_with_thousands_of_shapes_says_so_on_the_command_line(tmp_path, sample_path, monkeypatch, capsys):
    """Past HEAVY_ELEMENTS animated shapes the report warns that native players slow down (ThorVG may not load the
    file) and names the mobile preset; the CLI prints the report's warnings, which only the web page showed."""
    from converter.cli import main

    out = tmp_path / "face.json"
    args = ["convert", str(sample_path), "--to", "lottie", "--size", "96", "--end", "4", "-q", "-o", str(out)]
    assert main(args) == 0
    assert "warning" not in capsys.readouterr().err  # a small face: no warning
    monkeypatch.setattr(lottie, "HEAVY_ELEMENTS", 10)
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "facesvg: warning: this Lottie animates" in err and "--preset mobile" in err
