"""drive(): a FAP stream plus a face becomes a FaceAnimation; the CLI paths convert --fap and fdp --auto."""

from __future__ import annotations

import json

import numpy as np
import pytest

from converter import mpeg4
from converter.errors import InputError
from converter.mpeg4.fap import FapStream, read_fap

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sample(sample_path):
    from converter import formats

    return formats.load(sample_path)


@pytest.fixture(scope="module")
def joy(small_data):
    return read_fap(small_data / "mpeg4" / "xface" / "joy.fap")


def test_drive_sample_with_joy(sample, joy):
    anim = mpeg4.drive(sample, joy, ROOT / "samples" / "face.fdp.json")
    assert anim.n_frames == joy.n_frames == 108 and anim.fps == 25.0
    assert anim.n_vertices == sample.n_vertices and np.array_equal(anim.faces, sample.faces)
    assert anim.extras["fap"] == joy.name and anim.extras["faps_used"] == 42
    d = np.linalg.norm(anim.frames - sample.frames[0], axis=2)
    assert d.max() > 0.2  # it moves ...
    assert d[0].max() < d.max()  # ... more as the expression builds up
    assert np.isfinite(anim.frames).all()


def test_drive_finds_the_bundled_fdp_and_resamples(sample, joy):
    a = mpeg4.drive(sample, joy, None, fps=50)
    assert a.fps == 50 and a.n_frames == 216
    b = mpeg4.drive(sample, joy, ROOT / "samples" / "face.fdp.json")
    np.testing.assert_allclose(a.frames[::2][:50], b.frames[:50], atol=1e-4)


def test_zero_stream_gives_the_neutral(sample):
    s = FapStream("zero", 10, np.zeros((3, 68)), np.ones((3, 68), bool))
    a = mpeg4.drive(sample, s, ROOT / "samples" / "face.fdp.json")
    assert np.array_equal(a.frames, np.broadcast_to(sample.frames[0], a.frames.shape))


def test_drive_without_fdp_says_what_to_do(cube, joy):
    with pytest.raises(InputError, match=r"--fdp.*fdp INPUT --auto"):
        mpeg4.drive(cube, joy, None)


def test_cli_convert_with_fap(small_data, sample_path, tmp_path):
    from converter.cli import main

    out = tmp_path / "joy.svg"
    rc = main(["convert", str(sample_path), "--fap", str(small_data / "mpeg4" / "xface" / "joy.fap"),
               "--fdp", str(ROOT / "samples" / "face.fdp.json"), "--size", "96", "--end", "4", "-q", "-o", str(out)])
    assert rc == 0
    text = out.read_text()
    assert text.startswith("<?xml") or "<svg" in text[:400]
    bad = tmp_path / "bad.fap"
    bad.write_text("2.1 x 25 2\n" + "0 " * 68 + "\n0\n" + "0 " * 68 + "\n3\n")
    assert main(["convert", str(sample_path), "--fap", str(bad), "-o", str(tmp_path / "b.svg")]) == 2
    assert not (tmp_path / "b.svg").exists()


def test_cli_fdp_auto_on_sample(sample_path, sample, tmp_path, capsys):
    from converter.cli import main
    from converter.mpeg4.fdp import load_fdp

    out = tmp_path / "auto.fdp.json"
    assert main(["fdp", str(sample_path), "--auto", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "not found" in printed and "10.x" in printed  # it reports what it could not find
    auto = load_fdp(out, sample.frames[0])
    ref = load_fdp(ROOT / "samples" / "face.fdp.json")
    v = sample.frames[0]
    common = sorted(set(auto.points) & set(ref.points))
    err = [np.linalg.norm(v[auto.points[k]] - v[ref.points[k]]) / ref.fapu["ES0"] for k in common]
    assert len(common) >= 40 and np.median(err) < 0.15
    assert json.loads(out.read_text())["vertex_count"] == sample.n_vertices
    assert main(["fdp", str(sample_path), "-o", str(out)]) == 2  # --auto is required


def test_auto_on_ict_head_close_to_landmarks(shared_data):
    from converter.animation import FaceAnimation
    from converter.formats.ictfacekit import load_ict_head
    from converter.mpeg4.auto import auto_fdp
    from samples.ict_fdp import ict_fdp

    head = load_ict_head(shared_data / "ict_facekit")
    ref = ict_fdp(shared_data / "ict_facekit")
    fdp, report = auto_fdp(FaceAnimation(head.vertices[None], head.faces, head.part_ids, head.parts, 25, "ict"))
    v = head.vertices
    err = {k: np.linalg.norm(v[fdp.points[k]] - v[ref.points[k]]) / ref.fapu["ES0"]
           for k in fdp.points if k in ref.points}
    assert np.median(list(err.values())) < 0.1
    assert max(e for k, e in err.items() if not k.startswith("6.")) < 0.35  # auto's tongue includes the gums
    assert "9.12" in report.missing and "10.x" in report.missing and "3.5" in report.found and "2.13" in report.found
    assert fdp.fapu["MW0"] == pytest.approx(ref.fapu["MW0"], rel=0.2)


def test_auto_refuses_a_face_without_eyes(cube):
    from converter.mpeg4.auto import auto_fdp

    with pytest.raises(InputError, match="eyes"):
        auto_fdp(cube)


def test_drive_expands_a_reduced_stream(sample, joy):
    from converter.mpeg4 import loa
    from converter.mpeg4.fap import write_fap

    low = read_fap(write_fap(loa.reduce(joy, "low")))
    a = mpeg4.drive(sample, low, ROOT / "samples" / "face.fdp.json")
    b = mpeg4.drive(sample, loa.expand(loa.reduce(joy, "low")), ROOT / "samples" / "face.fdp.json")
    c = mpeg4.drive(sample, joy, ROOT / "samples" / "face.fdp.json")
    np.testing.assert_array_equal(a.frames, b.frames)
    # the low level keeps the gist: frames stay close to the full stream's
    err = np.linalg.norm(a.frames - c.frames, axis=2).max()
    assert 0 < err < 0.5 * np.linalg.norm(c.frames - sample.frames[0], axis=2).max()


def test_auto_uses_eye_openings_when_there_are_no_eyeballs(sample):
    from converter.animation import FaceAnimation
    from converter.mpeg4.auto import auto_fdp
    from converter.mpeg4.fdp import load_fdp

    keep = np.isin(sample.part_ids, [i for i, p in enumerate(sample.parts) if p.name not in ("eye", "iris")])
    face = FaceAnimation(sample.frames[:1], sample.faces[keep], sample.part_ids[keep], sample.parts, 30, "noeyes")
    fdp, report = auto_fdp(face)
    assert "left_eye" not in fdp.parts and "3.5" in fdp.positions and "3.5" not in fdp.points
    assert "eye opening" in report.missing["left_eye"]
    ref = load_fdp(ROOT / "samples" / "face.fdp.json")
    p, r = fdp.point_positions(sample.frames[0]), ref.point_positions(sample.frames[0])
    assert np.linalg.norm(p["3.5"] - r["3.5"]) < 0.1 * ref.fapu["ES0"]
    err = [np.linalg.norm(p[k] - r[k]) / ref.fapu["ES0"] for k in p if k in r]
    assert np.median(err) < 0.1
