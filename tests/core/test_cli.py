"""The facesvg command: conversion, info, and bad input (one line, exit 2, nothing written or touched)."""

import subprocess
import sys

import numpy as np
import pytest

BIN = [sys.executable, "-m", "converter.cli"]


def run(*args, cwd=None):
    return subprocess.run([*BIN, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.mark.slow
def test_convert_sample_writes_svg_and_summary(sample_path, tmp_path):
    out = tmp_path / "face.svg"
    r = run("convert", sample_path, "-o", out, "--size", "128", "--end", "10", "--report", tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes().startswith(b"<svg")
    assert "10 frames" in r.stdout and "triangles kept" in r.stdout
    assert (tmp_path / "r.json").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp file left


@pytest.mark.slow
def test_the_output_is_the_same_on_any_number_of_threads(sample_path, tmp_path):
    outs = []
    for threads in ("1", "3"):
        outs.append(tmp_path / f"face{threads}.svg")
        r = run("convert", sample_path, "-o", outs[-1], "--size", "256", "--end", "40", "--threads", threads)
        assert r.returncode == 0, r.stderr
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_info_describes_sample(sample_path):
    r = run("info", sample_path, "--json")
    assert r.returncode == 0, r.stderr
    import json

    info = json.loads(r.stdout)
    assert info["frames"] > 1 and info["triangles"] > 100 and "skin" in info["parts"]


@pytest.mark.parametrize(
    "content,needle",
    [
        (b"", "empty"),
        (b"\x00\x01garbage" * 10, "not a glTF"),
        (b"glTF\x02\x00\x00\x00\x10", ""),  # truncated GLB header
        (b'{"asset": {"version": "2.0"}}', "mesh"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_output(tmp_path, content, needle):
    src = tmp_path / "in.glb"
    src.write_bytes(content)
    out = tmp_path / "out.svg"
    r = run("convert", src, "-o", out)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("facesvg: error:"), r.stderr
    assert needle.lower() in lines[0].lower()
    assert "Traceback" not in r.stderr
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.glb"]


def test_failed_conversion_leaves_existing_output_untouched(tmp_path):
    src = tmp_path / "bad.glb"
    src.write_bytes(b"not a model")
    out = tmp_path / "out.svg"
    out.write_bytes(b"precious")
    r = run("convert", src, "-o", out)
    assert r.returncode == 2 and out.read_bytes() == b"precious"


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--size", "4"], "size"),
        (["--tolerance", "0"], "tolerance"),
        (["--start", "5", "--end", "2"], "range"),
        (["--shading", "toon"], "shading"),
        (["-o", "/nonexistent-folder/x.svg"], "folder"),
        (["--threads", "0"], "threads"),
        (["--threads", "two"], "threads"),
    ],
)
def test_bad_options_are_clear_errors(sample_path, args, needle):
    r = run("convert", sample_path, *args)
    assert r.returncode == 2 and needle in r.stderr.lower() and "Traceback" not in r.stderr


def test_missing_input_file(tmp_path):
    r = run("convert", tmp_path / "nope.glb")
    assert r.returncode == 2 and "does not exist" in r.stderr


def test_face_never_visible_is_a_clear_error():
    import numpy as np

    from converter.animation import FaceAnimation, Part
    from converter.convert import convert_animation
    from converter.errors import InputError
    from converter.options import ConversionOptions

    frames = np.array([[[0, 0, 0], [0, 1, 0], [1, 0, 0]]] * 3, np.float32)  # clockwise from the front: a back face
    anim = FaceAnimation(frames, np.array([[0, 1, 2]]), np.zeros(1, np.int32), (Part("skin", (1, 1, 1)),), 10.0)
    for opts in (ConversionOptions(size=64), ConversionOptions(size=64, shading="gouraud", frame=0)):
        with pytest.raises(InputError, match="no triangle is ever visible"):
            convert_animation(anim, opts)
    # Seen from behind (yaw 180) the same triangle faces the camera and converts.
    assert convert_animation(anim, ConversionOptions(size=64, yaw=180)).data.startswith(b"<svg")


def test_still_frame_outside_the_animation(sample_path, tmp_path):
    out = tmp_path / "x.svg"
    r = run("convert", sample_path, "--frame", "9999", "-o", out)
    assert r.returncode == 2 and "--frame 9999" in r.stderr and not out.exists()


@pytest.mark.slow
def test_single_obj_is_a_still_face(tmp_path):
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl skin\nf 1 2 3\n")
    out = tmp_path / "tri.svg"
    r = run("convert", obj, "-o", out, "--size", "64")
    assert r.returncode == 0, r.stderr
    assert "1 frames" in r.stdout and out.read_bytes().startswith(b"<svg")


@pytest.mark.slow
def test_convert_clones_onto_another_face(sample_path, small_data, tmp_path):
    """`convert --clone-target` runs the cloning stage: the SVG draws the target's triangles, animated."""
    import json

    from converter.verify import evaluate

    target = small_data / "mediapipe_canonical" / "canonical_face_model.obj"
    out = tmp_path / "cloned.svg"
    r = run("convert", sample_path, "-o", out, "--size", "128", "--end", "40", "--clone-target", target,
            "--report", tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["counts"]["vertices"] == 468 and report["counts"]["frames"] == 40
    ev = evaluate(out.read_bytes())
    assert ev.triangles.max() < 898  # the target's triangles, not the sample's 2,998
    moved = np.abs(ev.xy - ev.xy[:1]).max(axis=(2, 3))  # (T, P) px each path's vertices moved from frame 0
    assert moved.max() > 2.0  # the clone moves with the source's expressions and head motion


def test_progress_bar_shows_an_eta_from_the_progress_so_far(monkeypatch, capsys):
    from converter import cli
    from converter.options import seconds_left

    clock = iter([100.0, 104.0, 112.0])
    monkeypatch.setattr(cli.time, "monotonic", lambda: next(clock))
    bar = cli.ProgressBar(enabled=True)
    bar("extract", 0.0)
    bar("extract", 0.25)  # 4 s for a quarter: 12 s left
    bar("write", 0.5)  # 12 s for a half: 12 s left
    err = capsys.readouterr().err
    assert "ETA 0:12" in err.split("\r")[2] and "ETA 0:12" in err.split("\r")[3]
    assert "ETA" not in err.split("\r")[1]
    assert seconds_left(10.0, 0.01) is None and seconds_left(30.0, 0.5) == 30.0


def test_the_eta_counts_from_where_loading_ended(monkeypatch, capsys):
    # Loading (30 s here, a face driven by a long capture) has a guessed share of the bar (0.05 in convert, here
    # 1/16 for exact arithmetic): the ETA extrapolates from the progress made since, not from the start.
    from converter import cli
    from converter.options import Eta

    clock = iter([100.0, 120.0, 130.0, 140.0, 145.0])
    monkeypatch.setattr(cli.time, "monotonic", lambda: next(clock))
    bar = cli.ProgressBar(enabled=True)
    bar("load", 0.0)
    bar("weights", 0.03)
    bar("loaded", 0.0625)
    bar("simplify", 0.53125)  # half of what is after loading in 10 s: 10 s left (from the start: 35 s)
    bar("write", 0.765625)  # three quarters in 15 s: 5 s left
    err = capsys.readouterr().err.split("\r")
    assert "ETA 0:10" in err[4] and "ETA 0:05" in err[5], err
    eta = Eta()  # a conversion of a face in memory: no loading, counted from its first call
    assert eta("project", 0.125, 0.0) is None and eta("write", 0.5625, 5.0) == 5.0
    assert eta("done", 1.0, 9.0) is None


def test_preset_fills_only_the_flags_not_given():
    """--preset mobile --size 512 keeps 512 although 512 is the default; what is not given comes from the preset."""
    import argparse

    from converter.cli import add_conversion_options, options_from_args
    from converter.options import PRESETS

    p = argparse.ArgumentParser()
    add_conversion_options(p)
    mobile = PRESETS["mobile"].values
    o = options_from_args(p.parse_args(["--preset", "mobile", "--size", "512", "--tolerance", "0.25"]))
    assert (o.size, o.tolerance) == (512, 0.25)
    assert (o.max_triangles, o.max_animations) == (mobile["max_triangles"], mobile["max_animations"])
    assert options_from_args(p.parse_args(["--preset", "mobile"])).size == mobile["size"]
    d = options_from_args(p.parse_args([]))
    assert (d.size, d.rigid, d.occlusion) == (512, True, True)
