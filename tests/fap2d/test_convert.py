"""`facesvg convert face.glb --to fap2d --fap X.fap --fdp F.json` on the bundled sample with the real MPEG-4 engine."""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import reference_render

from converter.camera import Camera
from converter.cli import main
from converter.convert import convert_animation
from converter.errors import InputError
from converter.mpeg4 import deform, load_fdp, read_fap, tables_for
from converter.options import ConversionOptions
from converter.writers import fap2d

ROOT = Path(__file__).resolve().parents[2]
FDP = ROOT / "samples" / "face.fdp.json"
STREAMS = ("anger", "beg", "disgust", "fear", "happy-for", "hate", "joy", "pride")


def test_cli_writes_a_zip_next_to_the_input(sample_path, small_data, tmp_path, capsys):
    face = tmp_path / "face.glb"
    shutil.copy(sample_path, face)
    code = main(["convert", str(face), "--to", "fap2d", "--size", "192", "-q",
                 "--fap", str(small_data / "mpeg4/xface/anger.fap"), "--fdp", str(FDP)])
    assert code == 0, capsys.readouterr().err
    out = tmp_path / "face.zip"
    assert out.is_file() and "face.zip" in capsys.readouterr().out
    z = zipfile.ZipFile(out)
    manifest = json.loads(z.read("manifest.json"))
    jsonschema.validate(manifest, json.loads(fap2d.SCHEMA_PATH.read_text()))
    assert manifest["size"] == [192, 192] and manifest["stream"]["frames"] == 108
    assert z.read("stream.fap").decode().split()[0] in ("2.0", "2.1")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.slow
@pytest.mark.parametrize("name", STREAMS)
def test_every_xface_stream_makes_a_valid_package(name, sample_face, small_data):
    options = ConversionOptions(to="fap2d", size=128, fap=str(small_data / f"mpeg4/xface/{name}.fap"), fdp=str(FDP))
    result = convert_animation(sample_face, options)
    report = result.report
    assert result.extension == ".zip" and result.media_type == "application/zip"
    manifest = json.loads(zipfile.ZipFile(io.BytesIO(result.data)).read("manifest.json"))
    jsonschema.validate(manifest, json.loads(fap2d.SCHEMA_PATH.read_text()))
    dropped = {d["fap"] for d in manifest["dropped"]}
    assert {48, 49, 50, 14, 16, 17} <= dropped  # every Xface stream turns the head and pushes the lips
    assert {e["fap"] for e in manifest["fat2d"]["faps"]} >= {3, 4, 5, 19, 20, 23, 24, 25, 26}
    assert report.sizes["output"] == len(result.data) and report.counts["triangles_kept"] < report.counts["triangles"]


def test_neutral_frame_equals_portrait(joy_package):
    pkg = reference_render.load_package(joy_package)
    frame = reference_render.render_frame(pkg, np.zeros(68))
    inside = pkg.portrait[..., 3] == 255
    assert inside.mean() > 0.2
    # Exact, the lips' slit included: there the mouth layer (teeth and gums rendered alone) shows through at rest.
    assert np.array_equal(frame[inside], pkg.portrait[inside])
    slit = inside & (pkg.mouth[..., 3] > 0)
    assert slit.any()


def test_jaw_open_moves_the_chin_down_like_the_3d_engine(joy_package, sample_face):
    pkg = reference_render.load_package(joy_package)
    chin = np.array(pkg.manifest["feature_points"]["2.1"])
    k = int(np.linalg.norm(pkg.xy0 - chin, axis=1).argmin())
    v = np.zeros(68)
    v[2] = 400  # open_jaw, MNS units
    xy = reference_render.positions(pkg, v)
    assert xy[k, 1] - chin[1] > 4.0
    # The 3D engine, projected with the package's camera, puts the chin at the same place.
    neutral = sample_face.frames[0]
    fdp = load_fdp(FDP, neutral)
    tables = tables_for(neutral, sample_face.faces, fdp)
    moved = deform(neutral, tables, v[None], tables.fapu)[0][fdp.points["2.1"]]
    want = Camera.from_json(pkg.manifest["camera"]).project(moved.astype(np.float64))[0]
    assert np.abs(xy[k] - want).max() < 0.3
    # And the drawn chin goes lower: the texture around the chin point is now found where the table put it.
    frame = reference_render.render_frame(pkg, v)
    patch = lambda img, p: img[int(p[1]) - 3:int(p[1]) + 4, int(p[0]) - 3:int(p[0]) + 4].astype(float)  # noqa: E731
    moved_diff = np.abs(patch(frame, xy[k]) - patch(pkg.portrait, chin)).mean()
    static_diff = np.abs(patch(pkg.portrait, xy[k]) - patch(pkg.portrait, chin)).mean()
    assert moved_diff < static_diff / 2, (moved_diff, static_diff)


def test_sample_mouth_layer_comes_from_its_teeth(joy_package):
    pkg = reference_render.load_package(joy_package)
    assert pkg.manifest["layers"][1]["source"] == "render"
    ys, xs = np.nonzero(pkg.mouth[..., 3])
    fp = pkg.manifest["feature_points"]
    assert xs.min() < fp["2.2"][0] < xs.max() and ys.min() < fp["2.2"][1] < ys.max()


@pytest.mark.parametrize("case", ["no-fap", "no-fdp", "missing-fap", "malformed", "wrong-fdp"])
def test_bad_input_is_one_clear_error_and_nothing_written(case, sample_path, small_data, tmp_path, capsys):
    fap = small_data / "mpeg4/xface/joy.fap"
    args = ["convert", str(sample_path), "--to", "fap2d", "--size", "64", "-q", "-o", str(tmp_path / "out.zip")]
    if case == "no-fap":
        args += ["--fdp", str(FDP)]
        needle = "--fap"
    elif case == "no-fdp":
        args += ["--fap", str(fap)]
        needle = "--fdp"
    elif case == "missing-fap":
        args += ["--fap", str(tmp_path / "nope.fap"), "--fdp", str(FDP)]
        needle = "does not exist"
    elif case == "malformed":
        bad = tmp_path / "bad.fap"
        lines = fap.read_text().splitlines()
        lines[4] = lines[4].replace("1", "x", 1)
        bad.write_text("\n".join(lines) + "\n")
        args += ["--fap", str(bad), "--fdp", str(FDP)]
        needle = "line 5"
    else:
        args += ["--fap", str(fap), "--fdp", str(ROOT / "samples" / "ict.fdp.json")]
        needle = "vertices"
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("facesvg: error:") and needle in err and err.count("\n") == 1, err
    assert list(tmp_path.glob("*.zip")) == [] and list(tmp_path.glob(".out.zip*")) == []


def test_library_raises_input_error_without_stream(sample_face):
    with pytest.raises(InputError, match="FAP stream"):
        convert_animation(sample_face, ConversionOptions(to="fap2d", fdp=str(FDP)))


def test_fps_option_resamples_the_stream(sample_face, small_data):
    fap = small_data / "mpeg4/xface/joy.fap"
    options = ConversionOptions(to="fap2d", size=64, fps=50, fap=str(fap), fdp=str(FDP))
    pkg = reference_render.load_package(convert_animation(sample_face, options).data)
    assert pkg.manifest["stream"]["fps"] == 50 and pkg.n_frames == 216
    src = read_fap(fap).low_level()
    assert np.allclose(pkg.values[::2], src, atol=1e-6)  # every other frame is an original one
