"""The verifier: SMIL evaluation by hand, tolerance on the sample and on worst cases, and catching corruption."""

import dataclasses
import gzip
import re
import subprocess
import sys

import numpy as np
import pytest

from converter.convert import convert_animation
from converter.errors import InputError
from converter.options import ConversionOptions, Report
from converter.verify import evaluate, verify_animation
from converter.writers import svg_anim
from verify.ictface import ict_face
from verify.synth import fast_motion, flicker

CLI = [sys.executable, "-m", "converter.cli"]
META = ('<metadata id="facesvg">{"frames": 4, "fps": 2.0, "viewport": [10, 10], '
        '"camera": {}, "options": {"tolerance": 0.25}}</metadata>')


def hand_svg(body: str, viewbox: str = "0 0 20 20") -> bytes:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{viewbox}" width="10" height="10">{META}'
            f"<style>.h{{visibility:hidden}}</style><g>{body}</g></svg>").encode()


def test_a_triangle_collapsed_to_a_point_is_hidden():
    svg = hand_svg('<path id="f0" d="M0 0L4 0L0 4Z"><animate attributeName="d" dur="2s" repeatCount="indefinite" '
                   'keyTimes="0;.3;.6;1" values="M0 0L4 0L0 4Z;M2 2L2 2L2 2Z;m3 3 0 0 0 0z;M0 0L4 0L0 4Z"/></path>')
    ev = evaluate(svg)
    assert ev.shown[:, 0].tolist() == [True, True, False, True]  # u = 0, .25 (shrinking), .5 (a point), .75
    svg = svg.replace(b"0 0 0 0z", b"0 0 0 1z")
    assert evaluate(svg).shown[:, 0].tolist() == [True] * 4


def test_evaluates_keytimes_linear_discrete_and_viewbox_by_hand():
    # 4 frames at 2 fps: dur 2 s, frames at u = 0, .25, .5, .75. viewBox is 2x the viewport.
    svg = hand_svg(
        '<path id="f0" d="M0 0l2 0 0 2z"><animate attributeName="d" dur="2s" repeatCount="indefinite" '
        'keyTimes="0;.5;1" values="M0 0l2 0 0 2z;M8 4l2 0 0 2z;M8 4l2 0 0 2z"/>'
        '<animate attributeName="class" calcMode="discrete" dur="2s" repeatCount="indefinite" '
        'keyTimes="0;.7" values="a;h"/></path>'
        '<path id="f1" d="M0 0L4 0L4 4Z" visibility="hidden"><animate attributeName="visibility" calcMode="discrete" '
        'dur="2s" repeatCount="indefinite" values="hidden;visible"/></path>')
    ev = evaluate(svg)
    assert ev.triangles.tolist() == [0, 1]
    first_vertex = ev.xy[:, 0, 0]  # frame-by-frame, in viewport px (viewBox units / 2)
    np.testing.assert_allclose(first_vertex, [[0, 0], [2, 1], [4, 2], [4, 2]])
    np.testing.assert_allclose(ev.xy[1, 0, 2], [3, 2])  # relative l: (4 + 0 + 2) / 2, (2 + 0 + 2) / 2
    assert ev.shown[:, 0].tolist() == [True, True, True, False]  # class h from u = .7
    assert ev.shown[:, 1].tolist() == [False, False, True, True]  # 2 evenly spaced discrete values
    np.testing.assert_allclose(ev.xy[0, 1], [[0, 0], [2, 0], [2, 2]])


@pytest.mark.parametrize("tolerance", [0.1, 0.25, 1.0])
@pytest.mark.parametrize("make", [fast_motion, flicker], ids=["fast-motion", "flicker"])
def test_worst_cases_within_tolerance(make, tolerance):
    anim = make()
    result = convert_animation(anim, ConversionOptions(size=256, tolerance=tolerance, occlusion=False))
    v = verify_animation(result.data, anim)
    assert v.tolerance == tolerance
    assert v.max_px <= tolerance, v.summary()
    assert v.visibility_mismatches == 0, v.summary()
    assert v.vertex_frames > 1000


def test_flicker_really_flickers():
    anim = flicker()
    result = convert_animation(anim, ConversionOptions(size=256, occlusion=False))
    assert b'attributeName="class"' not in result.data  # hidden = collapsed in the d animation
    shown = evaluate(result.data).shown
    hidden_again = (np.diff(shown.astype(np.int8), axis=0) == -1).any(axis=0)
    shown_again = (np.diff(shown.astype(np.int8), axis=0) == 1).any(axis=0)
    assert (hidden_again & shown_again).sum() >= 30  # most triangles hide and show again
    assert verify_animation(result.data, anim).ok


@pytest.fixture(scope="module")
def ict_sheet(shared_data):  # the ICT head
    from converter import extract

    anim = ict_face(20, front=2.0, stride=3)
    return anim, extract.extract(anim, extract.fit_camera(anim, 256), occlusion=False)


@pytest.fixture(scope="module")
def sample_sheet(sample_path):
    from converter import extract, formats

    anim = formats.load(sample_path)
    return anim, extract.extract(anim, extract.fit_camera(anim, 256))


@pytest.mark.slow
@pytest.mark.parametrize("tolerance", [0.1, 0.25, 1.0])
@pytest.mark.parametrize("which", ["ict", "sample"])
def test_faces_within_tolerance(which, tolerance, ict_sheet, request):
    anim, sheet = ict_sheet if which == "ict" else request.getfixturevalue("sample_sheet")
    data = svg_anim.write(sheet, ConversionOptions(size=256, tolerance=tolerance), Report())
    v = verify_animation(data, anim)
    assert v.max_px <= tolerance and v.visibility_mismatches == 0, v.summary()
    assert v.paths > 500 and v.frames == anim.n_frames


@pytest.mark.slow
def test_sample_through_cli_svgz(sample_path, tmp_path):
    out = tmp_path / "face.svgz"
    r = subprocess.run([*CLI, "convert", sample_path, "-o", out, "--size", "128", "--tolerance", "0.1", "--svgz",
                        "--end", "40", "-q"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:2] == b"\x1f\x8b"
    r = subprocess.run([*CLI, "verify", out, sample_path, "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    import json

    figures = json.loads(r.stdout)
    assert figures["max_px"] <= 0.1 and figures["visibility_mismatches"] == 0 and figures["frames"] == 40


def _corrupt_one_value(svg: bytes, delta: int) -> bytes:
    """Move one coordinate of one key of the first animated path by delta viewBox units."""
    m = re.search(rb'values="m(-?\d+)', svg)
    return svg[: m.start(1)] + str(int(m.group(1)) + delta).encode() + svg[m.end(1):]


def test_verifier_catches_a_moved_key(tmp_path):
    anim = fast_motion()
    good = convert_animation(anim, ConversionOptions(size=256, occlusion=False)).data
    assert verify_animation(good, anim).ok
    bad = verify_animation(_corrupt_one_value(good, 40), anim)
    assert not bad.ok and bad.max_px > 1.0
    # One unit of the scaled viewBox is below the tolerance: a tiny corruption may pass, but is measured.
    tiny = verify_animation(_corrupt_one_value(good, 1), anim)
    assert tiny.max_px > 0


def test_verifier_catches_wrong_visibility():
    anim = flicker()
    good = convert_animation(anim, ConversionOptions(size=256, occlusion=False)).data
    bad = re.sub(rb'(values="[^"]*?) 0 0 0 0z', rb'\1 0 0 0 9z', good, count=3)  # three collapses undone
    assert bad != good
    v = verify_animation(bad, anim)
    assert v.visibility_mismatches > 0 and v.mismatch_frames > 0 and not v.ok


@pytest.mark.slow
def test_cli_verify_fails_on_corrupt_file_and_refuses_garbage(sample_path, tmp_path):
    out = tmp_path / "face.svg"
    r = subprocess.run([*CLI, "convert", sample_path, "-o", out, "--size", "128", "--end", "12", "-q"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ok = subprocess.run([*CLI, "verify", out, sample_path], capture_output=True, text=True)
    assert ok.returncode == 0 and "OK" in ok.stdout, ok.stdout + ok.stderr
    out.write_bytes(_corrupt_one_value(out.read_bytes(), 60))
    bad = subprocess.run([*CLI, "verify", out, sample_path], capture_output=True, text=True)
    assert bad.returncode == 1 and "FAIL" in bad.stdout
    garbage = tmp_path / "g.svg"
    garbage.write_bytes(b"<svg><oops")
    r = subprocess.run([*CLI, "verify", garbage, sample_path], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "not well-formed" in r.stderr


@pytest.mark.parametrize("data,needle", [
    (b"not xml at all", "not well-formed"),
    (b'<svg xmlns="http://www.w3.org/2000/svg"/>', "metadata"),
    (gzip.compress(b"<svg", mtime=0)[:10], "gzip"),  # mtime=0: the same test id in every process
])
def test_bad_svgs_raise_one_clear_error(data, needle):
    with pytest.raises(InputError, match=needle):
        evaluate(data)


def test_other_input_is_refused():
    svg = convert_animation(fast_motion(), ConversionOptions(size=64, occlusion=False)).data
    with pytest.raises(InputError, match="frames"):
        verify_animation(svg, fast_motion(n_frames=12))


def test_still_frames_verify_against_their_frame():
    anim = fast_motion()
    data = convert_animation(anim, ConversionOptions(size=128, frame=9, occlusion=False)).data
    v = verify_animation(data, anim)
    assert v.ok and v.frames == 1 and v.vertex_frames > 100
    wrong = data.replace(b'"frame":9', b'"frame":10')
    assert not verify_animation(wrong, anim).ok


def test_a_block_at_a_time_measures_what_all_the_paths_at_once_measure(sample_path, monkeypatch):
    """verify_animation evaluates and measures an SVG's paths a block at a time (a long capture's whole (T, P, 3, 2)
    positions took GBs): the figures, the worst vertex included, are those of every path measured at once."""
    from converter import formats, verify

    anim = formats.load(sample_path).sliced(0, 30)
    data = convert_animation(anim, ConversionOptions(size=96)).data
    ev = evaluate(data)
    camera = verify.Camera.from_json(ev.meta["camera"])
    whole = verify.compare(ev, *verify.exact_projection(anim, camera), anim.faces, 0.25)
    sizes = []
    real_add = verify._Tally.add

    def add(self, tris, *args):
        sizes.append(len(tris))
        return real_add(self, tris, *args)

    monkeypatch.setattr(verify._Tally, "add", add)
    monkeypatch.setattr(verify, "BLOCK_BYTES", 48 * 30 * 200)  # about 200 triangles a block
    blocked = verify_animation(data, anim)
    assert len(sizes) >= 5 and max(sizes) < 300 and sum(sizes) == len(ev.triangles)
    # the mean sums in another order (merged paths split across blocks): equal to rounding, every other figure exactly
    assert blocked.mean_px == pytest.approx(whole.mean_px, rel=1e-9)
    assert dataclasses.replace(blocked, mean_px=whole.mean_px) == whole
    assert blocked.worst == whole.worst and blocked.vertex_frames > 0


def test_the_worst_vertex_is_the_first_in_frame_path_vertex_order_whatever_the_blocks():
    """Blocks split the paths, while the whole measure reads (frame, path, vertex) in that order: of equal
    deviations the earliest frame wins even when its path comes in a later block."""
    from converter import verify

    t, faces = 4, np.array([[0, 1, 2], [3, 4, 5]])
    exact = np.zeros((t, 6, 2))
    xy = np.zeros((t, 2, 3, 2))
    xy[3, 0, 1, 0] = 0.2  # path 0's largest deviation, frame 3
    xy[1, 1, 2, 1] = 0.2  # path 1's, the same, frame 1: first in the whole array's order
    shown, visible = np.ones((t, 2), bool), np.ones((t, 2), bool)
    ev = verify.Evaluated({}, np.array([0, 1]), xy, shown)
    whole = verify.compare(ev, exact, visible, faces, 0.25)
    tally = verify._Tally(exact, visible, faces, 0.25)
    tally.add(np.array([0]), xy[:, :1], shown[:, :1], None)
    tally.add(np.array([1]), xy[:, 1:], shown[:, 1:], None)
    assert whole.worst == {"frame": 1, "triangle": 1, "vertex": 2, "px": pytest.approx(0.2)}
    assert tally.result() == whole


@pytest.mark.parametrize("values, rows", [
    ("M1 2L3 4L5 6Z", [[1, 2, 3, 4, 5, 6]]),
    ("m1 2 2 0 0 2z", [[1, 2, 3, 2, 3, 4]]),  # relative, the pairs after a moveto are linetos
    ("M0 0H4V3Z;M1 1h2v2z", [[0, 0, 4, 0, 4, 3], [1, 1, 3, 1, 3, 3]]),
    (" ;M0,0 L1,0 L0,1 Z; ", [[0, 0, 1, 0, 0, 1]]),  # blank values are left out
    # after a closepath the current point is the subpath's start; 4 triangles from 22 tokens (24 numbers out)
    ("M0 0H1 2ZH3 4 5ZH6 7 8ZH9 10 11Z", [[0, 0, 1, 0, 2, 0, 3, 0, 4, 0, 5, 0, 6, 0, 7, 0, 8, 0, 9, 0, 10, 0, 11, 0]]),
    ("M1e1 -.5l+2. 0 0 1E0", [[10, -0.5, 12, -0.5, 12, 0.5]]),
])
def test_values_of_a_d_animation_are_read_as_triangles(values, rows):
    from converter.verify import _d_rows

    assert _d_rows(values).tolist() == rows


@pytest.mark.parametrize("values, needle", [
    ("M0 0L1 1Z", "fewer than 3"),
    ("M0 0L1 0L0 1Z;M0 0L1 0Z", "fewer than 3"),
    ("M0 0L1 0L0 1ZL2 2", "fewer than 3"),
    ("M0 0L1 0L0 1Z;,", "fewer than 3"),  # a value with no token
    ("1 2", "path command ''"),
    ("M0 0L1 0L0 1Z3", "path command 'Z'"),
    ("M0 0L1 0L0 1Z;M0 0L1 0L0 1ZM2 2L3 2L2 3Z", "different numbers of triangles"),
])
def test_bad_values_of_a_d_animation_raise_one_clear_error(values, needle):
    from converter.verify import _d_rows

    with pytest.raises(InputError, match=re.escape(needle)):
        _d_rows(values)


@pytest.mark.parametrize("kind, width", [("translate", 1), ("translate", 2), ("scale", 1), ("scale", 2), ("rotate", 1),
                                         ("rotate", 3), ("skewX", 1), ("skewY", 1), ("matrix", 6)])
def test_a_transform_per_frame_is_built_with_the_bits_of_one_built_alone(kind, width):
    from converter.verify import _transform_matrix, _transform_stack

    rows = np.random.default_rng(7).normal(0, 40, (64, width)) * np.logspace(-3, 3, 64)[:, None]
    alone = np.stack([_transform_matrix(kind, list(row)) for row in rows])
    assert _transform_stack(kind, rows).tobytes() == alone.tobytes()


def test_a_transform_the_verifier_does_not_know_raises_one_clear_error():
    from converter.verify import _parse_transform, _transform_stack

    with pytest.raises(InputError, match="cannot be verified"):
        _transform_stack("matrix", np.ones((3, 5)))
    for text in ("translate()", "shear(3)", "matrix(1 0 0 1 0)"):
        with pytest.raises(InputError, match="cannot be verified"):
            _parse_transform(text)
