"""The puppet package: the command line, its size, the embedded take, `puppet-take`, and what the page may run."""

from __future__ import annotations

import gzip
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from converter.cli import main
from converter.convert import convert
from converter.errors import InputError
from converter.formats.captures.base import WeightTrack
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions, Report
from converter.puppet import from_track, puppet_of, resolve
from converter.puppet.model import Take
from converter.puppet.take import frame_times
from converter.writers import puppet as writer

CAPTURES = Path(__file__).resolve().parents[1] / "data" / "captures"
LLF = CAPTURES / "livelinkface_myslate3_cut.csv"  # 52 ARKit weights, head and eye angles, 24 frames
FACECAP = CAPTURES / "facecap_sample.txt"
SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "face.glb"


@pytest.fixture(scope="module")
def llf_result(face_path):
    return convert(face_path, ConversionOptions(to="puppet", weights=str(LLF)))


def test_cli_writes_a_puppet_with_the_take(face_path, tmp_path, capsys):
    out = tmp_path / "face.html"
    assert main(["convert", str(face_path), "--to", "puppet", "--weights", str(LLF), "-o", str(out), "-q"]) == 0
    page = out.read_bytes()
    assert writer.is_puppet(page)
    meta, data, take_meta, take = writer.read_blocks(page)
    assert take_meta["frames"] == read_weights(LLF).n_frames == 24
    assert take_meta["names"] == read_weights(LLF).names
    assert [m["name"] for m in meta["morphs"]] == ["browInnerUp", "eyeBlinkLeft", "jawOpen", "mouthSmileLeft"]
    assert len(take) >= 24 * 52


def test_the_take_costs_at_most_64_bytes_a_frame(llf_result):
    track = read_weights(LLF)
    take = from_track(track)
    assert len(track.names) == 52 and take.eyes is not None
    assert take.bytes_per_frame <= 64
    assert llf_result.report.sizes["take_bytes_per_frame"] == take.bytes_per_frame
    # the stored take grows with the frames, not with the mesh
    longer = Take(take.names, np.repeat(take.weights, 10, axis=0), take.fps,
                  None if take.head is None else np.repeat(take.head, 10, axis=0), np.repeat(take.eyes, 10, axis=0))
    raw = writer.encode_take(longer)[1]
    assert len(raw) <= 10 * take.n_frames * 64


def test_the_take_is_quantised_within_half_a_level(llf_result):
    track = read_weights(LLF)
    take = from_track(track)
    assert np.abs(take.weights / 255 - np.clip(track.values, 0, 1)).max() <= 0.5 / 255 + 1e-7


def test_package_is_small_and_only_moving_vertices_are_stored(llf_result, face):
    page = llf_result.data
    meta, data, _, _ = writer.read_blocks(page)
    assert len(gzip.compress(page)) < 80_000  # 1,053 vertices, 4 targets and a 24-frame take
    assert all(0 < m["moved"] < meta["vertices"] / 3 for m in meta["morphs"])


def test_blocks_decode_to_the_puppet(face_path):
    puppet = puppet_of(load_morph_face(face_path), ConversionOptions())
    meta, data, take_meta, take = writer.read_blocks(writer.write(puppet, ConversionOptions(), Report()))
    assert take_meta is None and take == b""
    a = meta["arrays"]
    xy, z, tris = writer.decode_mesh(data, meta)
    assert np.array_equal(xy, puppet.xy) and np.array_equal(z, puppet.z)
    assert np.array_equal(tris, puppet.triangles)
    assert np.array_equal(writer.decode_colors(data, meta), puppet.base_colors)
    assert np.array_equal(writer.decode_normals(data, meta), puppet.normals)
    assert len(writer.array(data, a["palette"])) < puppet.base_colors.size
    assert a["xy"][1] == a["tris"][1] == "zp"  # small integers, zigzag byte planes
    residual = 0
    for k, p in enumerate(puppet.morphs):
        ids, xy, z = writer.decode_parameter(data, meta, meta["morphs"][k])
        assert np.array_equal(ids, p.table.vertices)
        assert np.array_equal(xy, p.table.xy) and np.array_equal(z, p.table.z)
        assert meta["morphs"][k]["axes"][0] == list(p.axes[0])
        residual += bool(meta["morphs"][k].get("residual"))
    assert residual >= 1  # jawOpen's inner keyforms are stored as differences from the linear prediction
    assert np.array_equal(writer.array(data, a["e0.v"]), puppet.eyes[0])


def test_neutral_positions_are_on_the_stored_grid(puppet, face):
    """The neutral face is snapped to 1/16 px (and 2^-16 in depth) so the package stores it exactly as integers."""
    q = puppet.xy.astype(np.float64) * 16
    assert np.array_equal(q, np.rint(q))
    xy, z, _ = puppet.camera.project(face.base[puppet.source_vertices])
    assert 0 < np.abs(puppet.xy - xy).max() <= 1 / 32 + 1e-4
    assert np.abs(puppet.z - z).max() <= 2.0 ** -17 + 1e-6


def test_page_evaluates_no_strings_and_fetches_nothing(llf_result):
    page = llf_result.data.decode("utf-8")
    script = writer.puppet_script()
    for text in (page, script):
        for pattern in (r"\beval\s*\(", r"new\s+Function", r"\bfetch\s*\(", r"XMLHttpRequest", r"\bimport\s*\(",
                        r"setTimeout\s*\(\s*['\"]", r"<script[^>]+src=", r"<link[^>]+href=", r"https?://"):
            assert not re.search(pattern, text), pattern
    assert "new WebSocket(url)" in script  # the one connection: the live feed a user names


def test_puppet_take_replaces_only_the_take(tmp_path, llf_result, capsys):
    first = tmp_path / "a.html"
    first.write_bytes(llf_result.data)
    second = tmp_path / "b.html"
    assert main(["puppet-take", str(first), str(FACECAP), "-o", str(second)]) == 0
    a, b = first.read_bytes(), second.read_bytes()
    meta_a, data_a, take_a, _ = writer.read_blocks(a)
    meta_b, data_b, take_b, raw_b = writer.read_blocks(b)
    assert meta_a == meta_b and data_a == data_b
    track = read_weights(FACECAP)
    assert take_b["frames"] == track.n_frames == 40 and take_b["names"] == track.names
    assert take_a["frames"] == 24
    assert re.sub(rb'<script type="application/octet-stream" id="puppet-take".*?</script>', b"", a, flags=re.S) == \
        re.sub(rb'<script type="application/octet-stream" id="puppet-take".*?</script>', b"", b, flags=re.S)


def test_puppet_take_refuses_a_file_that_is_not_a_puppet(tmp_path, capsys):
    other = tmp_path / "x.html"
    other.write_text("<html></html>")
    assert main(["puppet-take", str(other), str(FACECAP), "-o", str(tmp_path / "y.html")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("facesvg: error: ") and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "y.html").exists()


def test_a_face_without_named_targets_is_one_clear_error(tmp_path, capsys):
    obj = tmp_path / "plain.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = tmp_path / "plain.html"
    assert main(["convert", str(obj), "--to", "puppet", "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("facesvg: error: ") and "named morph targets" in err and err.count("\n") == 1
    assert not out.exists()
    shapes = tmp_path / "neutral_only.zip"
    with zipfile.ZipFile(shapes, "w") as zf:
        zf.writestr("neutral.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError):
        convert(shapes, ConversionOptions(to="puppet"))


def test_a_capture_naming_no_target_is_one_clear_error(face_path, tmp_path):
    capture = tmp_path / "other.csv"
    capture.write_text("Timecode,BlendShapeCount,Foo,Bar\n00:00:00:00.000,2,0.5,0.1\n00:00:00:01.000,2,0.2,0.3\n")
    with pytest.raises(InputError, match="names a morph target"):
        convert(face_path, ConversionOptions(to="puppet", weights=str(capture)))


def test_still_frame_is_refused(face_path):
    with pytest.raises(InputError, match="--frame"):
        convert(face_path, ConversionOptions(to="puppet", frame=0))


def test_capture_names_resolve_as_the_player_resolves_them(llf_result, face_path):
    puppet = puppet_of(load_morph_face(face_path), ConversionOptions())
    m = resolve(puppet, ["JawOpen", "mouth_smile_L", "blendShape1.browInnerUp", "eyeBlink.L", "cheekPuff"])
    names = [p.name for p in puppet.morphs]
    assert m[0, names.index("jawOpen")] == 1 and m[1, names.index("mouthSmileLeft")] == 1
    assert m[2, names.index("browInnerUp")] == 1 and m[3, names.index("eyeBlinkLeft")] == 1
    assert not m[4].any()
    assert m.sum() == 4


def test_bundled_sample_builds_a_puppet_with_its_eyes():
    result = convert(SAMPLE, ConversionOptions(to="puppet", size=256))
    counts = result.report.counts
    assert counts["parameters"] == 9 and counts["eyes"] == 2
    assert 0 < counts["triangles_kept"] < counts["triangles"]
    meta, _, _, _ = writer.read_blocks(result.data)
    # ARKit's names reach the sample's ICT-style targets through the stored aliases
    assert meta["aliases"]["mouthSmileLeft"] == [[0, 1.0]]
    assert {k for k, _ in meta["aliases"]["browInnerUp"]} == {5, 6}


def test_an_irregular_take_keeps_its_own_times():
    rng = np.random.default_rng(3)
    times = np.cumsum(np.r_[0.0, rng.uniform(0.5, 3.0, 39) / 60])  # a recorder dropping and bunching rows
    track = WeightTrack(["jawOpen"], times, rng.uniform(0, 1, (40, 1)).astype(np.float32), 60.0,
                        head=rng.uniform(-0.3, 0.3, (40, 3)).astype(np.float32))
    assert not track.is_regular(tol=0.5)
    take = from_track(track)
    assert take.times is not None and take.bytes_per_frame == 1 + 6 + 2
    assert np.abs(frame_times(take) - (times - times[0])).max() <= 0.0005 + 1e-9  # to the millisecond
    regular = from_track(WeightTrack(["jawOpen"], np.arange(40) / 60, track.values, 60.0))
    assert regular.times is None and regular.bytes_per_frame == 1
