"""`facesvg info CAPTURE` describes a weight capture instead of refusing it as "not a face"."""

from __future__ import annotations

import json

from converter.cli import main
from tests.formats.captures.layout_samples import DATA


def test_info_describes_a_capture_in_text_and_json(tmp_path, capsys):
    path = DATA / "facecap_sample.txt"
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "layout: Face Cap TXT" in out and "frames: 40" in out and "fps: 30.0" in out
    assert main(["info", "--json", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["kind"] == "capture" and info["layout"] == "Face Cap TXT" and info["name"] == "facecap_sample"
    assert info["frames"] == 40 and info["fps"] == 30.0 and info["duration"] == 1.3333
    assert info["names"] == 6 and info["head_rotation"] is True and info["eye_rotation"] is True


def test_info_on_a_broken_capture_is_one_error_line(tmp_path, capsys):
    path = tmp_path / "take.csv"
    path.write_text("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,abc\n")
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("facesvg: error: take.csv row 2, column JawOpen") and err.count("\n") == 1


def test_info_on_a_missing_file_still_says_so(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.glb")]) == 2
    assert "does not exist" in capsys.readouterr().err
